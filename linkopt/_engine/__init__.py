"""The constraint engine (paper 001, Sec. II-III).

The engine takes built objects: the file layer (:mod:`linkopt._files`) reads a
mechanism file into one :class:`~linkopt._engine.model.Mechanism` (``model``); bodies
in maximal coordinates (``rotations``) are tied by joint residual
rows (``joints``, ``constraints``) whose Jacobians are written out (``jacobian``);
Levenberg–Marquardt (``lm``) solves forward and backward kinematics and their
sensitivities (``kinematics``; ``continuation`` carries a solved state to new
values); ``singularity`` gives σ_min and f_sing, ``mobility``
the rank at a state, ``statics`` and ``manipulability`` torques and velocity
ellipsoids; ``readout`` reads file-unit values off a state, and ``programs`` keeps
traced programs on disk. Its records are frozen dataclasses, the traced ones registered
pytrees (the documentation's Architecture page, Conventions).
"""
