"""Design evaluation: IK and adversarial samples over the target range, and
``f_design``.

``f_design`` (eq. 6) is the mean over targets ``t`` of
``f_BK(b^t, s_IK^t) + f_sing^c(s_adv^t)``: its first part (*reach*) is zero iff every
target was reached, its second (*singularity*) is zero iff no adversarial sample found
``f_sing > α₋``. The regulariser ``w ½|p - p₀|²`` (lengths divided by the reference
length) is reported separately; the optimiser minimises their sum.

A file with ``[collision]`` enabled adds a third part: ``weight`` times the
collision term (:func:`linkopt._engine.collision.collision_value`) averaged over the
IK and the collision sample states, i.e. ``weight · ½ (c(s_IK^t) + c(s_col^t))`` in
each target's summand. The IK samples are the poses the design must reach (a
collision there is one the box demands); the collision samples are adversarial
samples of clearance: each lane is run a second time, its IK minimisation followed by
a search for the pose of least clearance near the IK sample
(:func:`linkopt._design.objectives.clearance_objective`: the soft minimum of the
capsule pairs' clearances with eq. 5's range barrier and motion penalty), in the same
queue, as ``D·T`` more lanes. It is the term ``linkopt evaluate`` reports, and
``f_design - reach - singularity``; the collision samples are
:attr:`Evaluation.col_motors` and :attr:`Evaluation.col_states`. Whether any of it is
there is decided in Python from the file, so a file without it traces no collision
term (the two fields are None).

Targets: a grid of ``samples_per_dimension`` values per output spanning each range,
keeping the points on the box's boundary and, with ``interior = true``, the interior
ones too (3 per dimension, 2 outputs: 9 targets; 4 per dimension: 16; 3 per dimension,
3 outputs: 27, as the paper's Table I), then any ``[evaluation].targets`` the file
adds (an optimisation's verification rounds add them: :mod:`linkopt._design.run`). IK
starts from the rest pose for every target.
A batch of ``D`` designs is ``D·T`` independent lanes (``2·D·T`` with the collision
samples), each an IK minimisation followed by an adversarial one from its result, run
through
:func:`linkopt._design.sampling.minimise_queue` with ``QUEUE_WIDTH`` slots.

``QUEUE_WIDTH`` = 12 was chosen by timing the evaluation at several widths
(``benchmarks/bench_evaluation.py`` times it at this one): a lane-step costs more in a
wider batch (we think because a few dozen lanes' matrices stay in the
CPU caches, and because the trial solve's inner loop runs to its slowest lane), more
than the per-step overhead that favours width saves.

Each minimisation stops at its cap (``ik_iterations``, ``adversarial_iterations``: 40
by default), where the paper runs BFGS to convergence: under ``vmap`` every slot waits
for the slowest lane, so one lane that never converges (a target out of reach) would
hold up the batch. A capped adversarial sample may stop below the ``f_sing`` it would
reach, so ``f_design`` can read low; :func:`capped` counts the capped samples, and an
optimisation verifies its design densely before it stops.

``α₋`` is ``alpha_factor`` times ``f_sing`` at the rest pose of the file's *initial*
design, fixed for the whole optimisation so that a design cannot move its own threshold;
a rest pose near a singularity (:mod:`.conditioning`) gives no usable α₋, and the file
must then set ``alpha_minus`` (:func:`alpha_minus`).
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float, Int

from .._config import stored_record
from .._engine import programs
from .._engine.arguments import check_design
from .._engine.collision import collision_value, has_collision
from .._engine.constraints import homogenised_output_values, output_residual
from .._engine.geometry import design_vector, geometry, rest_state
from .._engine.lifting import padded_design
from .._engine.model import Mechanism, per_length
from .conditioning import alpha_minus
from .metrics import culled, thresholds
from .objectives import (
    adversarial_objective,
    clearance_objective,
    either,
    ik_objective,
)
from .sampling import Sample, minimise_queue

QUEUE_WIDTH = 12  # slots of the sample queue (module docstring)
#: How far outside the range (homogenised) an IK sample still counts as in it.
RANGE_SLACK = 1e-9


@stored_record("linkopt.Evaluation")
@dataclass(frozen=True)
class Evaluation:
    """One design's evaluation; a batch of designs adds a leading axis. Homogenised.
    With ``[collision]`` enabled, ``f_design`` also holds the weighted collision term
    (module docstring): ``f_design - reach - singularity``."""

    f_design: Float[Array, ""]
    reach: Float[Array, ""]
    singularity: Float[Array, ""]
    regularizer: Float[Array, ""]
    ik_motors: Float[Array, "T M"]
    ik_states: Float[Array, "T S"]
    ik_reach: Float[Array, " T"]  # f_BK(b^t, s_IK^t)
    ik_f_sing: Float[Array, " T"]
    adv_motors: Float[Array, "T M"]
    adv_states: Float[Array, "T S"]
    adv_f_sing: Float[Array, " T"]
    adv_culled: Float[Array, " T"]
    ik_iterations: Int[Array, " T"]
    adv_iterations: Int[Array, " T"]
    #: With ``[collision]`` enabled (else None): the collision samples, each the pose
    #: of least clearance found from its target's IK sample (module docstring).
    col_motors: Float[Array, "T M"] | None = None
    col_states: Float[Array, "T S"] | None = None

    @property
    def total(self):
        return self.f_design + self.regularizer


def targets(mech: Mechanism) -> np.ndarray:
    """IK target points ``b^t`` in file units, shape ``(T, K)``; traceable in the
    output ranges and the extra targets (:mod:`linkopt._engine.lifting`), numpy for
    concrete ones.

    The grid is ``np.linspace`` per output (``lo + k·step``, the last value ``hi``
    exactly); a point is on the boundary when one of its indices is first or last."""
    settings = mech.evaluation
    count, outputs = settings.samples_per_dimension, mech.num_outputs
    index = np.array(
        list(itertools.product(range(count), repeat=outputs)), dtype=int
    ).reshape(-1, outputs)
    xp = np if isinstance(mech.output_min, np.ndarray) else jnp
    lo, hi = mech.output_min, mech.output_max
    step = (hi - lo) / max(count - 1, 1)
    grid = (
        xp.where(index == count - 1, hi, index * step + lo)
        if count > 1
        else (xp.zeros(index.shape) + lo)
    )
    on_boundary = np.any((index == 0) | (index == count - 1), axis=1)
    grid = grid if settings.interior else grid[on_boundary]
    extra = xp.asarray(settings.targets, dtype=float).reshape(-1, outputs)
    return xp.concatenate([grid, extra])


def capped(mech: Mechanism, ev: Evaluation) -> tuple[int, int]:
    """How many IK and adversarial minimisations of ``ev`` (one design or a batch) ran
    to their iteration cap (module docstring); one that converged on its last allowed
    iteration counts as capped."""
    settings = mech.evaluation
    return (
        int(np.sum(np.asarray(ev.ik_iterations) >= settings.ik_iterations)),
        int(np.sum(np.asarray(ev.adv_iterations) >= settings.adversarial_iterations)),
    )


def regularizer(mech: Mechanism, design) -> Float[Array, ""]:
    """``w ½|p - p₀|²`` with lengths in reference lengths."""
    scale = per_length(mech.design.is_length, mech.length_scale)
    offset = (design - mech.design.p0) / scale
    return 0.5 * mech.evaluation.regularizer_weight * offset @ offset


def _lanes(mech: Mechanism, designs: Float[Array, "D n_p"], goals: Float[Array, "T K"]):
    """Each lane's geometry and target: ``D·T`` lanes, the targets of the first design
    first."""
    count, per_design = designs.shape[0], goals.shape[0]
    geoms = jax.vmap(lambda p: geometry(mech, p))(designs)
    lane_geoms = jax.tree_util.tree_map(
        lambda g: jnp.repeat(g, per_design, axis=0), geoms
    )
    return lane_geoms, jnp.tile(goals, (count, 1))


def _hunting(lanes):
    """The lanes twice over, with a third leaf that marks the second copy: the lanes
    whose second phase searches for the least clearance (module docstring)."""
    twice = jax.tree_util.tree_map(lambda a: jnp.concatenate([a, a]), lanes)
    count = lanes[1].shape[0]
    return (*twice, jnp.arange(2 * count) >= count)


def _halves(samples: Sample, count: int) -> tuple[Sample, Sample]:
    """The first ``count`` lanes' samples and the others'."""
    return (
        jax.tree_util.tree_map(lambda a: a[:count], samples),
        jax.tree_util.tree_map(lambda a: a[count:], samples),
    )


def _evaluation(
    mech: Mechanism,
    designs: Float[Array, "D n_p"],
    th,
    lanes,
    ik_samples: Sample,
    adv_samples: Sample,
    col_samples: Sample | None = None,
) -> Evaluation:
    """The ``D`` designs' evaluations from their lanes' IK, adversarial and (with
    ``[collision]`` enabled) collision samples."""
    lane_geoms, lane_goals = lanes
    count = designs.shape[0]
    per_design = lane_goals.shape[0] // count
    residuals = jax.vmap(lambda g, goal, s: output_residual(mech, g, goal, s))(
        lane_geoms, lane_goals, ik_samples.state
    )

    def per(a):  # lanes (D·T, ...) → (D, T, ...)
        return a.reshape((count, per_design) + a.shape[1:])

    reach = per(0.5 * jnp.sum(residuals**2, axis=1))
    adv_sing = adv_samples.f_sing
    adv_culled = per(culled(adv_sing, th))
    summands = reach + adv_culled
    collision = {}
    if col_samples is not None:  # static: without it, the program is as it was
        summands = summands + per(
            sample_collision(mech, lane_geoms, ik_samples.state, col_samples.state)
        )
        collision = {
            "col_motors": per(col_samples.motors),
            "col_states": per(col_samples.state),
        }
    return Evaluation(
        f_design=jnp.mean(summands, axis=1),
        reach=jnp.mean(reach, axis=1),
        singularity=jnp.mean(adv_culled, axis=1),
        regularizer=jax.vmap(lambda p: regularizer(mech, p))(designs),
        ik_motors=per(ik_samples.motors),
        ik_states=per(ik_samples.state),
        ik_reach=reach,
        ik_f_sing=per(ik_samples.f_sing),
        adv_motors=per(adv_samples.motors),
        adv_states=per(adv_samples.state),
        adv_f_sing=per(adv_sing),
        adv_culled=adv_culled,
        ik_iterations=per(ik_samples.iterations),
        adv_iterations=per(adv_samples.iterations),
        **collision,
    )


def sample_collision(mech: Mechanism, geoms, ik_states, col_states):
    """Each lane's share of the collision part of ``f_design`` (module docstring):
    ``weight · ½ (c(s_IK) + c(s_col))``, for lanes ``geoms`` (leading axis) with those
    sample states."""
    both = _collision_values(mech, geoms, ik_states) + _collision_values(
        mech, geoms, col_states
    )
    return (0.5 * mech.collision.weight) * both


def _collision_values(mech: Mechanism, geoms, states):
    """The collision term of each lane's state."""
    return jax.vmap(lambda g, s: collision_value(mech, g, s))(geoms, states)


def _evaluate_batch(
    mech: Mechanism, designs: Float[Array, "D n_p"], alpha
) -> Evaluation:
    """The evaluations of ``D`` designs (homogenised), every field with leading axis
    ``D``."""
    th = thresholds(alpha)
    goals = jnp.asarray(targets(mech) / mech.output_scale)
    low = jnp.asarray(mech.output_min / mech.output_scale)
    high = jnp.asarray(mech.output_max / mech.output_scale)
    lanes = _lanes(mech, designs, goals)
    count = designs.shape[0] * goals.shape[0]
    hunt = has_collision(mech)  # static: the collision samples' lanes (docstring)
    queued = _hunting(lanes) if hunt else lanes
    width = 2 * count if hunt else count
    rest = rest_state(mech)
    rest = jnp.broadcast_to(rest, (width,) + rest.shape)
    zero = jnp.zeros((width, mech.num_motors))
    settings = mech.evaluation

    def problem(lane, adversarial, anchor):
        geom, goal, *hunting = lane
        ik = ik_objective(mech, geom, goal, th)
        adv = adversarial_objective(mech, geom, anchor, low, high, th)
        if hunting:  # static
            closest = clearance_objective(mech, geom, anchor, low, high)
            adv = either(adv, closest, hunting[0])
        return geom, either(ik, adv, adversarial)

    iterations = (settings.ik_iterations, settings.adversarial_iterations)
    ik_samples, adv_samples = minimise_queue(
        mech, problem, queued, zero, rest, iterations, width=QUEUE_WIDTH
    )
    col_samples = None
    if hunt:
        ik_samples, _ = _halves(ik_samples, count)  # the other half: the same IK
        adv_samples, col_samples = _halves(adv_samples, count)
        col_samples = _not_below_start(
            mech,
            lanes,
            (low, high),
            (ik_samples, col_samples),
            _collision_values(mech, lanes[0], ik_samples.state),
            _collision_values(mech, lanes[0], col_samples.state),
        )
    adv_samples = _not_below_start(
        mech,
        lanes,
        (low, high),
        (ik_samples, adv_samples),
        ik_samples.f_sing,
        adv_samples.f_sing,
    )
    return _evaluation(mech, designs, th, lanes, ik_samples, adv_samples, col_samples)


def _not_below_start(mech, lanes, box, samples, start_score, end_score) -> Sample:
    """Each adversarial sample (``samples``: ``(start, end)``), or its start (the
    lane's IK sample) where that start has the larger score (``f_sing``; the
    collision term for a collision sample) and its outputs lie in the target range
    ``box`` ``(low, high)``.

    The adversarial minimisation (eq. 5) lowers ``f_sing^a`` plus the range barrier
    and the motion penalty, so from an IK sample on the box's boundary, where the
    barrier is steep, it can step inward and end at a lower ``f_sing`` than it started
    from (seen on the delta's deep box and a planar 3-RRR: 6 of 27 samples, by up to
    1-2 %): a barrier artefact, not a search that found nothing. The start is a
    configuration in the range with that larger ``f_sing``, so the sample of
    ``f_design`` is never below it.
    """
    (low, high), (start, end) = box, samples
    lane_geoms, _ = lanes
    outputs = jax.vmap(lambda g, s: homogenised_output_values(mech, g, s))(
        lane_geoms, start.state
    )
    slack = RANGE_SLACK  # a target on the boundary is reached to the LM tolerance
    inside = jnp.all((outputs >= low - slack) & (outputs <= high + slack), axis=1)
    keep = inside & (start_score > end_score)

    def pick(a, b):
        mask = keep.reshape(keep.shape + (1,) * (a.ndim - 1))
        return jnp.where(mask, a, b)

    return Sample(
        motors=pick(start.motors, end.motors),
        state=pick(start.state, end.state),
        value=end.value,
        f_sing=pick(start.f_sing, end.f_sing),
        iterations=end.iterations,
    )


def evaluate_homogenised(mech: Mechanism, designs, alpha) -> Evaluation:
    """The jitted core of :func:`evaluate`: homogenised designs, a given α₋."""
    if designs.ndim == 1:
        return jax.tree_util.tree_map(
            lambda a: a[0], _evaluate_batch(mech, designs[None], alpha)
        )
    return _evaluate_batch(mech, designs, alpha)


def _is_batch(design) -> bool:
    """Whether ``design`` is a 2-D stack of numbers (rows checked one by one)."""
    try:
        return design is not None and np.ndim(design) == 2
    except ValueError:  # ragged: check_design names it
        return False


def evaluate(mech: Mechanism, design=None) -> Evaluation:
    """Evaluate a design ``(n_p,)`` or a batch of designs ``(N, n_p)`` (file units);
    :class:`~linkopt.InputError` for any other shape or a value that is not finite."""
    if _is_batch(design):
        for k, row in enumerate(np.asarray(design)):
            check_design(mech, row, name=f"design[{k}]")
    else:
        check_design(mech, design)
    designs = padded_design(mech, design_vector(mech, design))
    alpha = jnp.asarray(alpha_minus(mech), dtype=jnp.float64)
    return programs.call("evaluate", mech, evaluate_homogenised, designs, alpha)


def batch_arguments(mech: Mechanism, rows: int) -> tuple:
    """Zeros shaped as the arguments :func:`evaluate` gives the evaluation program for
    a batch of ``rows`` designs (the designs, α₋)."""
    designs = padded_design(mech, np.zeros((rows, mech.design.size)))
    return designs, jnp.asarray(0.0, dtype=jnp.float64)


def batch_traced_before(mech: Mechanism, rows: int) -> bool:
    """Whether the evaluation of a batch of ``rows`` designs has been traced (and so,
    almost always, compiled) on this machine
    (:func:`linkopt._engine.programs.stored`)."""
    return programs.stored("evaluate", mech, *batch_arguments(mech, rows))


def evaluate_in_batch(mech: Mechanism, design, rows: int) -> Evaluation:
    """:func:`evaluate` of one design ``(n_p,)`` (None: the file's), computed as the
    first of ``rows`` copies of it: with ``rows`` the optimiser's chunk size, the
    program that evaluated the swarm serves it (in memory, or from the disk caches in
    another process) instead of a program for one design, which a first run would
    trace and compile again (``benchmarks/bench_compile.py`` lists them). A design's
    lanes do not depend on the other designs in the batch."""
    check_design(mech, design)
    single = np.asarray(design_vector(mech, design), dtype=np.float64)
    batch = evaluate(mech, np.repeat(single[None], max(int(rows), 1), axis=0))
    return jax.tree_util.tree_map(lambda a: a[0], batch)
