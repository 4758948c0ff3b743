"""The package's iterative solvers, one protocol, one module each.

A solver is a frozen dataclass holding its problem and settings, with

* ``init(y0) -> state``: the first iterate (a registered frozen dataclass with an
  ``iteration`` field, the loop's carry);
* ``step(state) -> state``: one iteration;
* ``terminate(state) -> (done, result)``: whether it stops, and why
  (:class:`~linkopt._engine.solvers.driver.Result`).

:func:`~linkopt._engine.solvers.driver.run` runs any of them in one ``lax.while_loop``
up to an iteration cap, jit- and vmap-friendly, failures as values. The shape is
optimistix's; the solvers are written here because the problems are tiny and
warm-started, where per-iteration overhead decides (``lm``'s docstring).

* :mod:`~linkopt._engine.solvers.lm`: Levenberg–Marquardt (the FK/BK solves, the
  assembly);
* :mod:`~linkopt._engine.solvers.quasi_newton`: the trust-region quasi-Newton of the
  design layer's samples (:mod:`linkopt._design.sampling`);
* :mod:`~linkopt._engine.solvers.projection`: Gauss–Newton projection onto the nearest
  point of ``{C = 0}`` (the assembly, :mod:`linkopt._files.assembly.solve`).
"""
