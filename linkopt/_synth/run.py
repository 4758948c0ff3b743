"""A synthesis run: the hybrid swarm + partial gradient of
:mod:`linkopt._design.optimizer` on the synthesis objective (:mod:`.objective`), then
the dense cycle sweep of the design it returns
(:func:`linkopt._synth.cycle.sweep_cycle`).

Per iteration every particle is scored in one batched call (the whole cycle of every
design, :func:`.objective.score`); personal and global bests follow pyswarms' rules;
each particle then takes, with probability ``gradient_probability``, a capped
partial-gradient step (:func:`.objective.gradients`), otherwise a swarm step, exactly
as an ``optimize`` run moves its particles. The returned design is the best one
scored, feasible first: a design is feasible when every target is within the
tolerance, the whole cycle was solved, no sampled row has ``f_sing`` above ``α₋`` and
no collision term is left. The run stops when a feasible design has not improved by
``improvement`` (relative) for ``patience`` iterations, or at ``iterations``.

The particles start around the file's design, spread by ``spread`` of each
parameter's range (wider than ``optimize``'s default: a synthesis starts from a
design that does not yet meet its target); for a planar four-bar path or function,
from the best closed-form starts instead (:func:`seeded`, :mod:`.starts`,
:mod:`.function_starts`). The swarm's design is
polished by least squares at the end and the polish kept where it ranks first
(:func:`polished`: the starts' closed-form fit for a planar four-bar path,
:mod:`.polish` on the swept cycle for any other mechanism).
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._design import optimizer as swarm_run
from .._design.evaluation import alpha_minus
from .._design.settings import OptimizerSettings
from .._engine.arguments import check_design
from .._engine.model import Mechanism
from .._errors import InputError
from . import fourbar, function_starts, starts
from .cycle import sweep_cycle
from .objective import Plan, Problem, Score, gradients, plan, score
from .polish import polish
from .sweep import reaching_timing
from .targets import Targets, check_targets

#: Closed-form starts scored before the swarm (at least the swarm's size), the best
#: kept exactly, and the spread of the other particles around them (a fraction of
#: each parameter's range).
CANDIDATES = 128
SEEDS = 4
SEED_SPREAD = 0.02
#: Defaults of a synthesis run (the swarm's meaning: :mod:`linkopt._design.optimizer`).
DEFAULT = OptimizerSettings(particles=32, iterations=40, spread=0.25, patience=5)


@dataclass(frozen=True)
class SynthesisResult:
    """What a synthesis returns: the design (file units) and its numbers. Distances
    in file units (rad for an angle output); ``traced`` and ``motors`` the swept
    cycle of the design (``(S, d)``, ``(S, M)``)."""

    design: np.ndarray
    targets: Targets
    plan: Plan
    distances: np.ndarray  # (k,)
    rows: np.ndarray  # (k,) the row of the cycle each target is met at
    traced: np.ndarray  # (S, d)
    solved: np.ndarray  # (S,)
    least_sigma: float  # least forward σ_min over the sampled rows
    alpha_minus: float
    parts: dict  # total, path, singularity, failure, collision (homogenised)
    feasible: bool
    history: tuple[dict, ...]
    seconds: float
    least_transmission_deg: float | None = None  # planar four-bars with a bound

    @property
    def rms(self) -> float:
        return float(np.sqrt(np.mean(self.distances**2)))

    @property
    def max_distance(self) -> float:
        return float(np.max(self.distances))

    @property
    def motors(self) -> np.ndarray:
        return self.plan.motors

    def summary(self) -> dict:
        """The JSON summary of the result (no arrays but the design)."""
        return {
            "kind": self.targets.kind,
            "name": self.targets.name,
            "targets": self.targets.count,
            "rms": self.rms,
            "max_distance": self.max_distance,
            "tolerance": self.targets.tolerance,
            "within_tolerance": bool(self.max_distance <= self.targets.tolerance),
            "cycle_solved": bool(np.all(self.solved)),
            "least_sigma_fk": self.least_sigma,
            "sigma_margin": self.least_sigma * self.alpha_minus / 2.0,
            "alpha_minus": self.alpha_minus,
            "least_transmission_deg": self.least_transmission_deg,
            "feasible": self.feasible,
            "iterations": len(self.history),
            "seconds": self.seconds,
            "parts": {k: float(v) for k, v in self.parts.items()},
            "design": [float(v) for v in self.design],
            "distances": [float(v) for v in self.distances],
        }


def _feasible(result: Score, tolerance: float) -> np.ndarray:
    return (
        np.all(np.asarray(result.distances) <= tolerance, axis=1)
        & np.all(np.asarray(result.solved), axis=1)
        & (np.asarray(result.singularity) <= 0.0)
        & (np.asarray(result.collision) <= 0.0)
        & (np.asarray(result.order) <= 0.0)
        & (np.asarray(result.transmission) <= 0.0)
    )


def _costs(result: Score) -> np.ndarray:
    total = np.asarray(result.total)
    return np.where(np.isfinite(total), total, np.inf)


TERMS = ("path", "singularity", "failure", "collision", "order", "transmission")
PARTS = (*TERMS, "rms")


def _record(run, result: Score, costs, chosen, seconds: float) -> dict:
    """The iteration's history row: the returned design's total and parts (carried
    over from the last row when the design is an earlier one) and this iteration's
    best total."""
    best = int(np.argmin(costs))
    head = {
        "iteration": run.iteration,
        "best_total": float(run.result_total),
        "feasible": bool(run.result_feasible),
        "iteration_total": float(costs[best]),
        "wall_time": seconds,
        "best_design": [float(v) for v in run.result_pos],
    }
    if chosen is None and run.history:
        return {**head, **{k: run.history[-1][k] for k in PARTS}}
    return {**head, **_parts(result, best if chosen is None else chosen)}


def _parts(result: Score, k: int) -> dict:
    return {
        **{name: float(getattr(result, name)[k]) for name in TERMS},
        "rms": float(np.sqrt(np.mean(np.asarray(result.distances[k]) ** 2))),
    }


def _score_step(mech, run, result: Score, settings, tolerance: float):
    """Bests and the returned design after scoring the positions (the optimiser's
    rules); the run and pyswarms' swarm for the move."""
    costs = _costs(result)
    feasible = _feasible(result, tolerance)
    swarm = swarm_run.swarm_of(run, settings, settings.inertia(run.iteration))
    previous = run.best_cost
    run = swarm_run.update_bests(run, swarm, costs)
    improved = run.best_cost < previous
    run, chosen = swarm_run.update_result(run, feasible, costs, settings, improved)
    return run, swarm, costs, chosen


def _move(mech, problem, run, swarm, result, settings, alpha):
    """The optimiser's move (:func:`linkopt._design.optimizer.move_particles`) with
    the synthesis objective's partial gradient."""

    def partial(position):
        return gradients(mech, problem, position, result, alpha)

    return swarm_run.move_particles(mech, run, swarm, settings, partial)


def synthesize(
    mech: Mechanism,
    targets: Targets,
    settings: OptimizerSettings | None = None,
    *,
    steps: int = 360,
    span: tuple[float, float] | None = None,
    progress: Callable[[dict], None] | None = None,
    resume: swarm_run.SwarmRun | None = None,
    checkpoint: Callable[[swarm_run.SwarmRun], None] | None = None,
) -> SynthesisResult:
    """A design of ``mech`` whose cycle meets ``targets`` (module docstring).
    ``steps``: rows of the swept cycle; ``span``: the motor range of an open
    one-motor target without timing whose motor has no limits (default a full turn
    for a rotary motor); ``progress`` receives each iteration's history row;
    ``checkpoint`` the run after each iteration's move (the state to score next),
    and ``resume`` such a run to continue instead of a fresh swarm (the same end as
    an uninterrupted run: every step is deterministic)."""
    settings = settings or DEFAULT
    targets = check_targets(mech, targets)
    problem = _problem(mech, targets, steps, span)
    alpha = alpha_minus(mech)
    began = time.perf_counter()
    if resume is None:
        run = seeded(mech, problem, settings, alpha, swarm_run.start(mech, settings))
    else:
        run = resume
    while True:
        result = score(mech, problem, run.position, alpha)
        run, swarm, costs, chosen = _score_step(
            mech, run, result, settings, targets.tolerance
        )
        record = _record(run, result, costs, chosen, time.perf_counter() - began)
        run = dataclasses.replace(run, history=(*run.history, record))
        if progress is not None:
            progress(record)
        if swarm_run.converged(run, settings):
            break
        run = _move(mech, problem, run, swarm, result, settings, alpha)
        if checkpoint is not None:
            checkpoint(run)
    design = polished(mech, problem, run.result_pos, settings, alpha)
    result = finish(mech, problem, design, alpha, run.history, began)
    return dataclasses.replace(result, targets=targets)


def _problem(mech: Mechanism, targets: Targets, steps: int, span) -> Problem:
    """The swept problem of ``targets``. A multi-motor target without timing is
    fitted at the motor values that reach its targets with the file's design
    (:func:`.sweep.reaching_timing`): the designs are scored on that motion, and the
    result keeps the targets untimed, so that :func:`verify` reaches each target
    again with the result's own design and sweeps the straight motor-space motion
    between consecutive ones. One fixed timing is a choice: a timing that followed
    each design would need an IK solve per particle and target in every score."""
    if targets.motors is None and mech.num_motors > 1:
        timing = reaching_timing(mech, mech.design.p0, targets)
        targets = dataclasses.replace(targets, motors=timing)
    return Problem(targets, plan(mech, targets, steps, span))


def _padded(designs: np.ndarray, size: int) -> np.ndarray:
    """``designs`` repeated up to ``size`` rows (the swarm's batch: one compiled
    score for the run)."""
    reps = -(-size // len(designs))
    return np.tile(designs, (reps, 1))[: max(size, len(designs))]


def _ranked(result: Score, tolerance: float) -> np.ndarray:
    """Indices of scored designs, feasible first, then by total."""
    feasible = _feasible(result, tolerance)
    return np.lexsort((_costs(result), ~feasible))


def seeded(mech, problem: Problem, settings, alpha, run):
    """The swarm's first positions: for a planar four-bar path
    (:func:`.starts.applies`) ``CANDIDATES`` closed-form starts
    (:func:`.starts.candidates`), for a planar four-bar function generation the
    Freudenstein starts (:func:`.function_starts.candidates`); the swarm's size of
    the best of them scored with the whole cycle in one batch, the best
    ``SEEDS`` kept exactly (the best first) with the file's design, the other
    particles spread by ``SEED_SPREAD`` of each range around them; otherwise the
    optimiser's start around the file's design, unchanged."""
    targets = problem.targets
    if starts.applies(mech, targets):
        found = starts.candidates(
            mech,
            targets,
            seed=settings.seed,
            count=max(settings.particles, CANDIDATES),
            min_transmission_deg=targets.min_transmission_deg,
            full_turn=problem.plan.cyclic,
        )
    elif function_starts.applies(mech, targets):
        found = function_starts.candidates(mech, targets)
    else:
        return run
    if len(found) == 0:
        return run
    size = settings.particles
    found = found[:size]  # the refinement's best, scored in one batch
    result = score(mech, problem, _padded(found, size), alpha)
    costs = _costs(result)[: len(found)]
    feasible = _feasible(result, targets.tolerance)[: len(found)]
    order = np.lexsort((costs, ~feasible))
    best = found[order[: min(SEEDS, len(found))]]
    kept = np.vstack([best, mech.design.p0[None]])
    rng = np.random.default_rng(settings.seed)
    d = mech.design
    spread = SEED_SPREAD * (d.upper - d.lower)
    around = kept[np.arange(size) % len(best)]
    moved = around + rng.uniform(-1.0, 1.0, around.shape) * spread
    position = np.clip(np.vstack([kept, moved[len(kept) :]])[:size], d.lower, d.upper)
    return dataclasses.replace(
        run,
        position=position,
        pbest_pos=position.copy(),
        best_pos=position[0].copy(),
    )


def polished(mech, problem: Problem, design, settings, alpha) -> np.ndarray:
    """The run's design, or its least-squares polish where that is better: for a
    planar four-bar path :func:`.starts.refine_batch` (the path error with the
    transmission bound, on the closed-form coupler curve), for any other mechanism
    :func:`.polish.polish` (the distances on the swept cycle). The polish is scored
    with the whole cycle beside the design and kept only when it ranks first:
    feasible before not, then the lower total."""
    targets = problem.targets
    design = np.asarray(design, dtype=float)
    if starts.applies(mech, targets):
        fit = starts.problem_of(
            mech, targets, targets.min_transmission_deg, problem.plan.cyclic
        )
        fine = starts.refine_batch(mech, fit, design[None])[0][0]
    else:
        fine = polish(mech, problem, design, alpha, batch=settings.particles)
    pair = np.stack([design, fine])
    result = score(mech, problem, _padded(pair, settings.particles), alpha)
    return pair[int(_ranked(result, targets.tolerance)[0]) % 2]


def finish(mech, problem: Problem, design, alpha, history=(), began=None):
    """The :class:`SynthesisResult` of ``design`` (scored alone)."""
    design = np.asarray(design, dtype=float)
    check_design(mech, design)
    result = score(mech, problem, design[None], alpha)
    one = {
        f.name: np.asarray(getattr(result, f.name))[0]
        for f in dataclasses.fields(result)
    }
    parts = {k: float(one[k]) for k in ("total", *TERMS)}
    feasible = bool(_feasible(result, problem.targets.tolerance)[0])
    traced = one["traced"]
    if problem.targets.kind == "function":
        traced = traced[:, 0]
    return SynthesisResult(
        design=design,
        targets=problem.targets,
        plan=problem.plan,
        distances=one["distances"],
        rows=one["rows"],
        traced=traced,
        solved=one["solved"],
        least_sigma=float(one["least_sigma"]),
        alpha_minus=float(alpha),
        parts=parts,
        feasible=feasible,
        history=tuple(history),
        seconds=0.0 if began is None else time.perf_counter() - began,
        least_transmission_deg=(
            float(np.degrees(one["least_transmission"]))
            if problem.static(mech)[5]
            else None
        ),
    )


def score_design(
    mech: Mechanism, targets: Targets, design=None, *, steps: int = 360, span=None
) -> SynthesisResult:
    """The :class:`SynthesisResult` numbers of one design (None: the file's) without
    optimising: its cycle, distances and terms."""
    targets = check_targets(mech, targets)
    problem = _problem(mech, targets, steps, span)
    design = mech.design.p0 if design is None else design
    result = finish(mech, problem, design, alpha_minus(mech))
    return dataclasses.replace(result, targets=targets)


def four_bar_summary(mech: Mechanism, design) -> dict | None:
    """Grashof class, link ratio and the transmission angle's worst distance from a
    straight line over a full crank turn (degrees) of a planar four-bar's ``design``
    (the closed forms of :mod:`linkopt._synth.fourbar`); None for another
    mechanism."""
    try:
        placed = fourbar.read_four_bar(mech, design)
    except InputError:
        return None
    shape = placed.four_bar()
    return {
        "grashof": fourbar.grashof_class(shape),
        "link_ratio": fourbar.link_ratio(shape),
        "transmission_worst_deg": float(np.degrees(fourbar.transmission(shape).worst)),
    }


def verify(mech: Mechanism, result: SynthesisResult, *, steps: int | None = None):
    """The dense cycle sweep (:func:`linkopt._synth.cycle.sweep_cycle`) of a result's
    design over the same motion; its report's ``defect`` names the first defect met,
    None when there is none. An open curve of a crank without limits is swept over
    the crank's full turn, as a closed one (the targets in cyclic order). The motor
    may run either way: where the targets are out of order one way, the other is
    swept too, and the report that finds them in order returned."""
    steps = steps or result.plan.steps
    targets = result.targets
    if result.plan.cyclic and not targets.closed:
        targets = dataclasses.replace(targets, closed=True)
    if targets.closed or targets.motors is not None or mech.num_motors > 1:
        report = sweep_cycle(mech, result.design, targets, steps=steps)
        if report.in_order or targets.motors is not None or mech.num_motors > 1:
            return report
        back = sweep_cycle(mech, result.design, targets, steps=steps, direction=-1)
        return back if back.in_order else report
    motors = result.plan.motors[:, 0]
    span = (float(motors.min()), float(motors.max()))
    report = sweep_cycle(mech, result.design, targets, steps=steps, span=span)
    if report.in_order:
        return report
    back = sweep_cycle(mech, result.design, targets, steps=steps, span=span[::-1])
    return back if back.in_order else report
