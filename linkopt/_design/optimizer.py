"""Hybrid particle swarm + partial gradient design optimisation (paper Sec. V).

Per iteration: all particles are evaluated in one batched call; personal and global
bests are updated (pyswarms' rules: personal bests and the star topology,
:mod:`linkopt._design.swarm`); then each particle
independently, with probability ``gradient_probability`` (½ in the paper), takes a
partial-gradient step (:mod:`linkopt._design.partial`), otherwise a swarm step
``v ← w v + c₁ r₁ (p_best - x) + c₂ r₂ (g_best - x)``, ``x ← x + lr · v``, with the
inertia ``w`` falling linearly from 0.9 to 0.4 over 100 iterations, ``c₁ = c₂ = 2``,
``lr = 1``. Positions are kept in bounds by the ``nearest`` rule; ties
(symmetry) hold by construction since ``p`` is the reduced parameter vector.

The swarm's random numbers ``r₁, r₂`` come from the run's explicit seed
(``numpy.random.Generator``), never numpy's global random state.

Partial-gradient step: in scaled parameters (lengths divided by the reference length)
``Δ = -g · min(gradient_rate, gradient_step / |g|)``, i.e. a gradient step whose length
is capped at ``gradient_step`` reference lengths; the particle's velocity is unchanged.

The design a run returns is the best one it evaluated, ranked first by whether its
``f_design`` is at most ``tolerance`` (the whole range reached with no singularity, up
to solver noise) and then by total (``f_design`` + regulariser). The swarm itself
follows the global best by total, which may be a design with a tiny but non-zero
``f_design`` and a smaller regulariser; ranking feasibility first keeps such a design
from being returned or from holding the run open. ``tolerance`` = 1e-12 is our choice:
feasible five-bar, finger, neck and Jansen designs score 1e-27 to 1e-18 (reach residuals
at the solver's constraint tolerance), while one adversarial sample a fraction ``t`` of
the way from ``α₋`` to ``α₊`` adds about ``10 t³ α₋ / T`` to ``f_design``. 1e-6 is too
loose: with it a five-bar run (seed 2) returned a design at 7e-8, a sample 0.06 % above
``α₋``, and ``linkopt verify`` found ``f_sing`` 0.6 % above ``α₋`` on its grid; 1e-12
admits ``t ≈ 3e-5`` on the five-bar (0.0014 % above ``α₋``) or a reach miss of 4e-6
(homogenised output units). The run stops once the returned design is feasible and its
total has not dropped by more than ``improvement`` (relative) for ``patience``
iterations, or at ``iterations``. ``improvement`` = 1e-3 is our choice: the paper says
only that it stops when the objective stops improving, and regulariser gains below 0.1 %
do not change a design in any way a user would notice.

Before a run stops, it verifies its design densely (:mod:`linkopt._design.run`): where
verification fails, the failing places become IK targets and :func:`reopen` continues
the run for up to ``iterations`` more iterations, at most ``verify_rounds`` times.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from jaxtyping import Bool, Float

from .._engine.mobility import mobility_changes
from .._engine.model import Mechanism
from .collision import COLLISION_COLUMNS, history_columns
from .evaluation import Evaluation, alpha_minus
from .settings import OptimizerSettings
from .swarm import BoundaryHandler, Star, compute_pbest, compute_position, create_swarm
from .workers import Workers


@dataclass(frozen=True, eq=False)
class SwarmRun:
    """Everything needed to continue a run exactly: the swarm, the RNG and the history.

    Immutable: :func:`step` returns a new run (:func:`dataclasses.replace`) and leaves
    its argument as it was, so an earlier run stays valid beside the later ones.
    Shapes: ``N`` particles, ``n_p`` design parameters.
    """

    iteration: int
    position: Float[np.ndarray, "N n_p"]
    velocity: Float[np.ndarray, "N n_p"]
    pbest_pos: Float[np.ndarray, "N n_p"]
    pbest_cost: Float[np.ndarray, " N"]
    best_pos: Float[np.ndarray, " n_p"]
    best_cost: float
    rng_state: dict
    history: tuple[dict, ...]  # one record per finished iteration
    stalled: int = 0  # iterations since the returned design last improved
    finished: bool = False
    result_pos: Float[np.ndarray, " n_p"] | None = None  # returned (module docstring)
    result_total: float = float("inf")
    result_feasible: bool = False
    #: the iteration count at which the run stops at the latest (:func:`reopen`)
    limit: int = 0
    #: the verification rounds so far (:mod:`linkopt._design.run`), oldest first
    rounds: tuple[dict, ...] = ()

    @property
    def added_targets(self) -> tuple[tuple[float, ...], ...]:
        """The IK targets (file units) that the verification rounds added."""
        return tuple(tuple(t) for r in self.rounds for t in r["added_targets"])


def start(mech: Mechanism, settings: OptimizerSettings) -> SwarmRun:
    """Particles uniformly around ``p₀`` (the first one exactly ``p₀``), zero
    velocity."""
    rng = np.random.default_rng(settings.seed)
    d = mech.design
    offsets = (
        rng.uniform(-1.0, 1.0, size=(settings.particles, d.size))
        * settings.spread
        * (d.upper - d.lower)
    )
    offsets[0] = 0.0
    position = np.clip(d.p0 + offsets, d.lower, d.upper)
    return SwarmRun(
        iteration=0,
        position=position,
        velocity=np.zeros_like(position),
        pbest_pos=position.copy(),
        pbest_cost=np.full(settings.particles, np.inf),
        best_pos=d.p0.copy(),
        best_cost=float("inf"),
        rng_state=rng.bit_generator.state,
        history=(),
        limit=settings.iterations,
    )


def reopen(run: SwarmRun, settings: OptimizerSettings) -> SwarmRun:
    """The finished ``run`` continued for up to ``settings.iterations`` more iterations
    once a verification round has added IK targets: every best is forgotten (their
    costs were of the old targets), so the next evaluation, of the same positions,
    scores them again."""
    return dataclasses.replace(
        run,
        pbest_cost=np.full_like(run.pbest_cost, np.inf),
        best_cost=float("inf"),
        stalled=0,
        finished=False,
        result_total=float("inf"),
        result_feasible=False,
        limit=run.iteration + settings.iterations,
    )


def swarm_of(run: SwarmRun, settings: OptimizerSettings, inertia: float):
    swarm = create_swarm(
        n_particles=run.position.shape[0],
        dimensions=run.position.shape[1],
        options={"c1": settings.cognitive, "c2": settings.social, "w": inertia},
    )
    swarm.position = run.position.copy()
    swarm.velocity = run.velocity.copy()
    swarm.pbest_pos = run.pbest_pos.copy()
    swarm.pbest_cost = run.pbest_cost.copy()
    swarm.best_pos = run.best_pos.copy()
    swarm.best_cost = run.best_cost
    return swarm


def gradient_moves(
    mech: Mechanism, gradients: np.ndarray, settings: OptimizerSettings
) -> np.ndarray:
    scale = np.where(mech.design.is_length, mech.length_scale, 1.0)
    scaled = gradients * scale
    norm = np.linalg.norm(scaled, axis=1, keepdims=True)
    factor = np.minimum(
        settings.gradient_rate, settings.gradient_step / np.maximum(norm, 1e-300)
    )
    return -scaled * factor * scale


def _costs(ev: Evaluation) -> Float[np.ndarray, " N"]:
    """Each particle's total, infinite where it is not finite."""
    costs = ev.f_design + ev.regularizer
    return np.where(np.isfinite(costs), costs, np.inf)


def update_bests(run: SwarmRun, swarm, costs: np.ndarray) -> SwarmRun:
    """Personal and global bests after this iteration's evaluation (pyswarms' rules);
    ``swarm`` takes them too."""
    swarm.current_cost = costs
    swarm.pbest_pos, swarm.pbest_cost = compute_pbest(swarm)
    swarm.best_pos, swarm.best_cost = Star().compute_gbest(swarm)
    return dataclasses.replace(
        run,
        pbest_pos=swarm.pbest_pos,
        pbest_cost=swarm.pbest_cost,
        best_pos=np.asarray(swarm.best_pos),
        best_cost=float(swarm.best_cost),
        finished=False,
    )


def update_result(
    run: SwarmRun,
    feasible: np.ndarray,
    costs: np.ndarray,
    settings: OptimizerSettings,
    swarm_improved: bool,
) -> tuple[SwarmRun, int | None]:
    """Keep the best design seen (feasible first, then by total) and count stalled
    iterations; also the particle of this iteration that is now the returned design,
    or None when it is an earlier one. ``swarm_improved``: whether this iteration
    lowered the swarm's best total (then the swarm's best is this iteration's best
    particle, pyswarms' star topology)."""
    if not feasible.any():
        chosen = None
        if not run.result_feasible:  # nothing feasible yet: the swarm's best
            run = dataclasses.replace(
                run,
                result_pos=np.asarray(run.best_pos).copy(),
                result_total=run.best_cost,
            )
            chosen = _iteration_best(costs) if swarm_improved else None
        return dataclasses.replace(run, stalled=run.stalled + 1), chosen
    k = int(np.argmin(np.where(feasible, costs, np.inf)))
    improved = not run.result_feasible or costs[k] < run.result_total * (
        1.0 - settings.improvement
    )
    chosen = None
    if not run.result_feasible or costs[k] < run.result_total:
        run = dataclasses.replace(
            run,
            result_pos=run.position[k].copy(),
            result_total=float(costs[k]),
            result_feasible=True,
        )
        chosen = k
    return dataclasses.replace(run, stalled=0 if improved else run.stalled + 1), chosen


#: The history columns that describe the returned design (:func:`record_iteration`).
RUNNING_PARTS = ("best_total", "best_f_design", "regularizer", "reach", "singularity")


def _iteration_best(costs: np.ndarray) -> int:
    """The particle with the lowest total, NaN (a failed evaluation) counting as
    worst."""
    return int(np.argmin(np.where(np.isnan(costs), np.inf, costs)))


def _parts(ev: Evaluation, costs: np.ndarray, k: int, extra: dict) -> dict:
    """Particle ``k``'s total and its parts, as the history names them."""
    return {
        "best_total": float(costs[k]),
        "best_f_design": float(ev.f_design[k]),
        "regularizer": float(ev.regularizer[k]),
        "reach": float(ev.reach[k]),
        "singularity": float(ev.singularity[k]),
        **extra,
    }


def _returned_parts(
    run: SwarmRun,
    ev: Evaluation,
    costs: np.ndarray,
    chosen: int | None,
    columns: Callable[[int], dict],
) -> dict:
    """``best_total`` and its parts for the history: those of the design the run
    returns (:func:`best_design`; feasible first, then by total), so that the progress
    line, ``history.csv``, ``summary.json`` and the convergence plot give one design's
    numbers. ``chosen``: the particle of this iteration that is that design
    (:func:`update_result`), else the design is an earlier one and its numbers carry
    over from the previous record. A verification round adds IK targets, which changes
    every cost (:func:`reopen` forgets the returned design's for the same reason), so
    the numbers restart with the round; the record's ``round`` says which round it
    belongs to. ``columns(k)``: more columns of particle ``k`` (the collision columns,
    :func:`linkopt._design.collision.history_columns`)."""
    previous = run.history[-1] if run.history else None
    same_round = previous is not None and previous.get("round", 0) == len(run.rounds)
    if chosen is None and same_round:
        keys = (*RUNNING_PARTS, *COLLISION_COLUMNS)
        return {k: previous[k] for k in keys if k in previous}
    k = _iteration_best(costs) if chosen is None else chosen  # nothing finite yet
    return _parts(ev, costs, k, columns(k))


def record_iteration(
    run: SwarmRun,
    ev: Evaluation,
    costs: np.ndarray,
    chosen: int | None = None,
    columns: Callable[[int], dict] = lambda k: {},
) -> SwarmRun:
    """``run`` with the iteration's history row appended (the run loop adds
    ``wall_time``): the returned design's total and parts (:func:`_returned_parts`,
    with ``feasible``, whether it is feasible) and, as ``iteration_total`` and
    ``iteration_f_design``, this iteration's best particle's."""
    best = _iteration_best(costs)
    record = {
        "iteration": run.iteration,
        **_returned_parts(run, ev, costs, chosen, columns),
        "feasible": bool(run.result_feasible),
        "iteration_total": float(costs[best]),
        "iteration_f_design": float(ev.f_design[best]),
        "round": len(run.rounds),
        "swarm_best_total": run.best_cost,
        "evaluations": (run.iteration + 1) * len(costs),
        "limit": run.limit,
    }
    record["best_design"] = [float(v) for v in run.result_pos]
    return dataclasses.replace(run, history=(*run.history, record))


def score(
    mech: Mechanism,
    run: SwarmRun,
    ev: Evaluation,
    settings: OptimizerSettings,
    refused: Bool[np.ndarray, " N"] | None = None,
):
    """``run`` after this iteration's evaluation ``ev`` of its positions: bests,
    returned design and history row (not yet moved); and the pyswarms swarm with the
    bests, for the move. ``refused`` particles (a design that changes the mobility)
    cost infinity and are infeasible."""
    costs = _costs(ev)
    feasible = np.asarray(ev.f_design) <= settings.tolerance
    if refused is not None:
        costs = np.where(refused, np.inf, costs)
        feasible = feasible & ~refused
    swarm = swarm_of(run, settings, settings.inertia(run.iteration))
    previous_best = run.best_cost
    run = update_bests(run, swarm, costs)
    improved = run.best_cost < previous_best
    run, chosen = update_result(run, feasible, costs, settings, improved)
    position = run.position
    run = record_iteration(
        run, ev, costs, chosen, lambda k: history_columns(mech, ev, position, k)
    )
    return run, swarm


def converged(run: SwarmRun, settings: OptimizerSettings) -> bool:
    """Whether the run stops after this iteration (module docstring)."""
    return (
        run.result_feasible and run.stalled >= settings.patience
    ) or run.iteration + 1 >= run.limit


def move_particles(
    mech: Mechanism,
    run: SwarmRun,
    swarm,
    settings: OptimizerSettings,
    partial_gradient: Callable[[np.ndarray], np.ndarray],
) -> SwarmRun:
    """Every particle's move: a partial-gradient step or a swarm step (module
    docstring), drawn from the run's RNG; the next iteration's run.
    ``partial_gradient(positions)`` gives the partial gradients ``(N, n_p)`` at the
    run's positions (called only when some particle takes a gradient step). Shared
    by ``optimize`` and the synthesis run (:mod:`linkopt._synth.run`)."""
    rng = np.random.default_rng()
    rng.bit_generator.state = run.rng_state
    use_gradient, velocity = swarm_moves(rng, run, settings)
    swarm.velocity = np.where(
        use_gradient[:, None], run.velocity, settings.learning_rate * velocity
    )
    bounds = (mech.design.lower, mech.design.upper)
    moved = compute_position(swarm, bounds, BoundaryHandler(strategy="nearest"))
    if use_gradient.any():
        gradients = partial_gradient(run.position)
        gradients = np.where(np.isfinite(gradients), gradients, 0.0)
        stepped = np.clip(
            run.position + gradient_moves(mech, gradients, settings), *bounds
        )
        moved = np.where(use_gradient[:, None], stepped, moved)
    return dataclasses.replace(
        run,
        position=np.asarray(moved),
        velocity=np.where(use_gradient[:, None], run.velocity, swarm.velocity),
        rng_state=rng.bit_generator.state,
        iteration=run.iteration + 1,
    )


def _move(
    mech: Mechanism,
    run: SwarmRun,
    swarm,
    ev: Evaluation,
    settings: OptimizerSettings,
    workers: Workers,
) -> SwarmRun:
    """:func:`move_particles` with the workers' partial gradient."""
    return move_particles(
        mech,
        run,
        swarm,
        settings,
        lambda position: workers.partial_gradient(position, ev, alpha_minus(mech)),
    )


def step(
    mech: Mechanism,
    run: SwarmRun,
    settings: OptimizerSettings,
    workers: Workers | None = None,
) -> SwarmRun:
    """One iteration, from a run to the next: evaluate, update bests, record, then move
    every particle (or mark the run finished).

    ``workers`` splits the batched evaluation and gradients over processes (default:
    this process only)."""
    workers = workers or Workers(mech)
    ev = workers.evaluate(run.position)
    refused = _mobility_refused(mech, run.position)
    run, swarm = score(mech, run, ev, settings, refused.mask)
    if refused.columns:  # this iteration's, not the returned design's
        *before, record = run.history
        run = dataclasses.replace(run, history=(*before, {**record, **refused.columns}))
    if converged(run, settings):
        return dataclasses.replace(run, finished=True, iteration=run.iteration + 1)
    return _move(mech, run, swarm, ev, settings, workers)


@dataclass(frozen=True)
class Refused:
    """The particles whose design changes the mobility at rest (they count as
    infeasible, with an infinite cost), and the history columns that say so: how many,
    and the first one's reason (:meth:`MobilityChange.words`)."""

    mask: Bool[np.ndarray, " N"]
    columns: dict


def _mobility_refused(mech: Mechanism, designs: np.ndarray) -> Refused:
    changes = mobility_changes(mech, designs)
    mask = np.array([c is not None for c in changes], dtype=bool)
    if not mask.any():
        return Refused(mask, {})
    first = changes[int(np.argmax(mask))]
    return Refused(
        mask, {"refused": int(mask.sum()), "refused_reason": first.words(mech)}
    )


def swarm_moves(
    rng: np.random.Generator, run: SwarmRun, settings: OptimizerSettings
) -> tuple[Bool[np.ndarray, " N"], Float[np.ndarray, "N n_p"]]:
    """Which particles take a gradient step, and everyone's swarm velocity (Sec. V)."""
    n = run.position.shape[0]
    use_gradient = (
        np.ones(n, bool)
        if settings.mode == "gradient"
        else rng.random(n) < settings.gradient_probability
    )
    r1 = rng.random(run.position.shape)
    r2 = rng.random(run.position.shape)
    inertia = settings.inertia(run.iteration)
    velocity = (
        inertia * run.velocity
        + settings.cognitive * r1 * (run.pbest_pos - run.position)
        + settings.social * r2 * (run.best_pos - run.position)
    )
    return use_gradient, velocity


def best_design(run: SwarmRun) -> Float[np.ndarray, " n_p"]:
    """The design the run returns: the best seen so far, feasible first (module
    docstring)."""
    return run.result_pos
