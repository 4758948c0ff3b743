"""Mechanism files: reading one into a :class:`~linkopt._engine.model.Mechanism` and
writing a design back.

``loader`` reads a file part by part, in the order the parts depend on each other:
``topology`` (bodies and joints), ``bounds`` (the reference length and the magnitudes a
file may give), ``points`` (named points, motors, idle spins), ``outputs`` and
``settings`` (``[solver]``, ``[evaluation]``); ``writer`` writes a design back as a
file. The file layer uses the engine (the field reader :mod:`linkopt._engine.fields`,
the model, the readers of design parameters, symmetry and collision that build engine
structures, and the assembly of a drawn file); the engine never imports it.
"""
