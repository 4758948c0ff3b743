"""Mechanism files: reading one into a :class:`~linkopt._engine.model.Mechanism` and
writing a design back.

``loader`` reads a file part by part, in the order the parts depend on each other:
``topology`` (bodies and joints), ``bounds`` (the reference length and the magnitudes a
file may give), ``points`` (named points, motors, idle spins), ``outputs`` and
``settings`` (``[solver]``, ``[evaluation]``), ``design_space`` (with
``design_kinds`` and ``design_angles``: ``[[design]]`` as one linear map),
``symmetry``, ``collision``, and ``assembly/`` (a drawn file's loops closed); ``fields``
is the typed field reader they all use; ``writer`` writes a design back as a file. The
file layer builds the engine's objects (:mod:`linkopt._engine.model`); the engine takes
them and never imports this layer.
"""
