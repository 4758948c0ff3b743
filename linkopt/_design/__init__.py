"""Design optimisation on the engine (paper 001, Sec. IV-V).

In pipeline order: ``settings`` (a run's settings and the commands' limits, without
JAX), ``metrics`` (the culled and attractive singularity metrics, the barrier),
``sampling`` (IK and adversarial sample minimisers), ``evaluation``
(f_design, eq. 6), ``partial`` (the partial gradient), ``swarm`` and ``optimizer``
(the hybrid particle swarm), ``workers`` (processes sharing the particles) and
``ahead`` (those processes spawned before the mechanism is loaded), ``run``
(run folders, checkpoints, outputs), ``verify`` (the dense check of a result), ``maps``
(continuation grids), ``plot_maps`` and ``space_plots`` (motor- and end-effector-space
figures), ``plots`` (the mechanism and convergence figures), ``motion`` and
``animation`` (frames along a path and their GIF).
"""
