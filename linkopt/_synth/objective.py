"""The synthesis objective: a design's whole cycle swept, its traced curve scored
against the targets, plus ``f_design``'s singularity and collision terms.

**The sweep** (:func:`plan`, :func:`.continuation.sweep`). The motors pass through
``S`` rows in order (``(S, M)``, file units): for a closed curve one full turn of the
one motor from its rest value; for an open one without timing the motor's
``[[motors]]`` span, else ``span``, else (a rotary motor without limits) the same
full turn as a closed curve, the targets' order then cyclic (``Plan.cyclic``);
with timing, straight segments through the timing rows, each target at a known row
(its ``at``). Each row is reached from the last by the engine's predictor-corrector
step (:func:`.continuation.step_to`; the first row from the rest pose by
:func:`linkopt._engine.kinematics.continue_to`), so the design stays on its rest
pose's branch; a row it cannot reach (a dead point, no assembly) ends the lane's
sweep: the rows after it are not solved (``solved`` false) and the design scores the
failure term. The designs of a batch are swept together: one scan over the rows,
each step vmapped over the designs, with no Python loop over rows.

**The score** of one design (homogenised; the swarm minimises ``total``):

* ``path = ½ mean_k (d_k / ρ)²``: ``d_k`` the distance from target ``k`` to the traced
  quantity at its row (timing), else to the nearest traced row (a path's refined to
  the two segments at that row, :func:`_to_segments`); ``ρ`` the reference
  length for positions, the output's scale for a function. A motion target's distance
  is ``√(|Δx|² + (ρ θ)²)``, ``θ`` the angle between the orientations: one radian
  counts as one reference length.
* ``singularity = mean_s f_sing^c(s)`` over every row: ``f_sing^c`` of
  eq. 7 (zero below ``α₋``, the culled term of ``f_design``'s adversarial samples),
  taken on the cycle itself instead of on adversarial samples of a target box, of
  ``f = 2 / σ_min^FK``. Only the forward singularity counts: the motor drives the
  cycle, and a backward one is where the outputs stop and turn back (a crank-rocker's
  rocker at each end of its swing), which every full-turn crank meets. ``2 / σ``
  compares with ``α₋``, a multiple of the rest pose's ``1/σ_FK + 1/σ_BK``, as that
  sum would for equal ``σ``;
* ``failure = FAILURE_WEIGHT · (unsolved rows / S)``;
* ``collision = weight · mean_s c(s)`` over every ``stride``-th row, where
  ``[collision]`` is on;
* ``order = ORDER_WEIGHT · min(Σ_k max(0, t_k − t_{k+1})², reversed) / S²``
  (:func:`descents`): ``t_k`` the place (fractional row) where target ``k`` is met,
  for a full turn from the first target's place modulo ``S``. Zero exactly when the
  targets are met in order, either sense of the motor; continuous in the design;
* ``transmission = TRANSMISSION_WEIGHT · mean_s max(0, μ_req − μ_s)²`` for a planar
  four-bar whose targets ask ``min_transmission_deg`` (:func:`four_bar_transmission`):
  ``μ_s`` the transmission angle's distance from a straight line at row ``s``.

Every term but ``path`` is zero for a design without defects, so once the defects
are gone the path error alone is minimised. ``total`` is their sum; the file's
regulariser (the pull towards the file's design) is left out: a synthesis moves a
design as far as its target asks.

**The gradient** (:func:`gradients`) is the optimiser's partial gradient
(:mod:`linkopt._design.partial`): each target's row and the row of largest ``f_sing``
with their motors frozen, through the same adjoint; the failure and collision terms
are left to the swarm.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Bool, Float, Int

from .._config import stored_record
from .._design.metrics import culled, thresholds
from .._design.partial import adjoint_term
from .._engine import programs
from .._engine.collision import collision_value, has_collision
from .._engine.constraints import (
    homogenised_joint_positions,
    homogenised_output_values,
    homogenised_point_positions,
)
from .._engine.geometry import geometry
from .._engine.jacobian import state_jacobian
from .._engine.lifting import padded_design
from .._engine.model import Mechanism
from .._engine.singularity import sigmas_of
from .._errors import InputError
from .continuation import sweep
from .targets import FULL_TURN, Targets

#: Weight of the unsolved fraction of the cycle (module docstring): above any
#: path error a design that completes its cycle can have.
FAILURE_WEIGHT = 10.0
#: Rows between the collision samples of the score.
STRIDE = 4
#: Weight of the order penalty (module docstring): a target passed a tenth of the
#: cycle out of its place costs ``0.1``.
ORDER_WEIGHT = 10.0
#: Weight of the transmission penalty: a degree short on every row costs ``3e-4``,
#: a path miss of about 2.5 % of the reference length.
TRANSMISSION_WEIGHT = 1.0


@dataclass(frozen=True)
class Plan:
    """The motion a sweep follows (numpy, fixed for a run): ``motors`` ``(S, M)`` file
    units in order; ``at`` ``(k,)`` the row of each target under timing, else None."""

    motors: np.ndarray
    at: np.ndarray | None
    closed: bool
    stride: int = STRIDE
    cyclic: bool = False  # the rows are one full turn (the targets' order cyclic)

    @property
    def steps(self) -> int:
        return len(self.motors)


def plan(
    mech: Mechanism, targets: Targets, steps: int = 360, span=None, stride=STRIDE
) -> Plan:
    """The sweep for ``targets`` (module docstring); ``span`` ``(low, high)`` the
    motor range of an open one-motor curve without timing when the motor has no
    limits."""
    if targets.motors is not None:
        motors, at = _timed(mech, targets, steps)
        return Plan(motors, at, targets.closed, stride)
    turn = np.linspace(0.0, FULL_TURN, steps, endpoint=False)[:, None]
    if targets.closed:
        return Plan(turn, None, True, stride, cyclic=True)
    low_high = _span(mech, span)
    if low_high is None:  # a crank without limits: its full turn, cyclic order
        return Plan(turn, None, False, stride, cyclic=True)
    low, high = low_high
    return Plan(np.linspace(low, high, steps)[:, None], None, False, stride)


def _span(mech: Mechanism, span) -> tuple[float, float] | None:
    """The open sweep's motor span; None for a rotary motor without limits (its
    full turn from rest: a crank meets an open curve's targets somewhere along its
    turn, in their order from the first)."""
    if mech.motor_limited and np.all(np.isfinite([mech.motor_min, mech.motor_max])):
        return float(mech.motor_min[0]), float(mech.motor_max[0])
    if span is not None:
        return float(span[0]), float(span[1])
    if not bool(mech.motor_linear[0]):
        return None
    from .._errors import MechanismFileError

    raise MechanismFileError(
        mech.source,
        f"[[motors]] {mech.motor_names[0]!r}",
        "an open target without timing needs the linear motor's min and max (its span)",
    )


def _wrap(mech: Mechanism, rows: np.ndarray) -> np.ndarray:
    """What a closed timed curve adds to its first row to end its cycle: a full turn
    onwards, in the direction the timing turns, for one rotary motor (the crank goes
    round, it does not turn back); nothing otherwise (back to the first row)."""
    if mech.num_motors != 1 or bool(mech.motor_linear[0]):
        return np.zeros(rows.shape[1])
    return np.array([FULL_TURN * np.sign(rows[-1, 0] - rows[0, 0])])


def _timed(mech: Mechanism, targets: Targets, steps: int):
    """Straight segments through the timing rows (a closed curve back to the first,
    :func:`_wrap`),
    ``steps`` rows in all, shared by the segments in proportion to their length."""
    rows = targets.motors
    ends = np.vstack([rows, rows[:1] + _wrap(mech, rows)]) if targets.closed else rows
    scale = np.asarray(mech.motor_scale)
    lengths = np.max(np.abs(np.diff(ends, axis=0)) / scale, axis=1)
    share = lengths / max(lengths.sum(), 1e-300)
    counts = np.maximum(1, np.round(share * (steps - 1)).astype(int))
    pieces, at = [rows[:1]], [0]
    for k, count in enumerate(counts):
        t = np.linspace(0.0, 1.0, count + 1)[1:, None]
        pieces.append(ends[k] + t * (ends[k + 1] - ends[k]))
        at.append(at[-1] + count)
    motors = np.vstack(pieces)
    return motors, np.asarray(at[: len(rows)])


@stored_record("linkopt.SynthesisScore")
@dataclass(frozen=True)
class Score:
    """Designs' scores (module docstring), leading axis ``D``; homogenised terms,
    distances in file units (rad for an angle output)."""

    total: Float[Array, " D"]
    path: Float[Array, " D"]
    singularity: Float[Array, " D"]
    failure: Float[Array, " D"]
    collision: Float[Array, " D"]
    distances: Float[Array, "D k"]
    rows: Int[Array, "D k"]  # the row each target is scored at
    solved: Bool[Array, "D S"]
    least_sigma: Float[Array, " D"]  # least σ_min^FK over the solved rows
    traced: Float[Array, "D S d"]  # file units
    states: Float[Array, "D S n"]
    worst: Int[Array, " D"]  # the row of largest f_sing
    order: Float[Array, " D"]  # the order penalty (zero: targets met in order)
    transmission: Float[Array, " D"]  # the transmission penalty (planar four-bars)
    least_transmission: Float[Array, " D"]  # rad; π/2 where not a four-bar


def _static(targets: Targets, mech: Mechanism) -> tuple[str, int]:
    """The traced quantity's kind and index (point, output or body)."""
    names = {
        "path": mech.point_names,
        "function": mech.output_names,
        "motion": mech.body_names,
    }[targets.kind]
    return targets.kind, list(names).index(targets.name)


def quantity(mech: Mechanism, geom, state, kind: str, index: int):
    """The traced quantity of one state, homogenised: a point ``(3,)``, an output
    ``(1,)`` or a body's pose ``(7,)``."""
    if kind == "path":
        return homogenised_point_positions(mech, geom, state)[index]
    if kind == "function":
        return homogenised_output_values(mech, geom, state)[index : index + 1]
    return state[7 * index : 7 * index + 7]


def distance(a, b, kind: str):
    """Homogenised distance between two traced quantities (module docstring)."""
    gap = jnp.sum((a[:3] - b[:3]) ** 2)
    if kind == "motion":
        dot = jnp.abs(jnp.dot(a[3:], b[3:]))
        sine = jnp.sqrt(jnp.maximum(1.0 - dot * dot, 0.0) + 1e-300)
        gap = gap + (2.0 * jnp.arctan2(sine, dot)) ** 2
    return jnp.sqrt(gap + 1e-300)


def to_file(mech: Mechanism, kind: str, index: int):
    """Per-coordinate factors from homogenised traced quantities to file units."""
    if kind == "function":
        return jnp.asarray(mech.output_scale)[index : index + 1]
    if kind == "path":
        return jnp.full(3, mech.length_scale)
    return jnp.concatenate([jnp.full(3, mech.length_scale), jnp.ones(4)])


def forward_sigma(mech: Mechanism, geom, state):
    """``σ_min`` of ``∂C_FK/∂s`` at one state (homogenised), differentiable."""
    return sigmas_of(state_jacobian(mech, geom, "fk", state)[None])[0]


def _to_segments(traced, goal, row, solved, cyclic: bool):
    """Distance from ``goal`` to the traced polyline's two segments at ``row`` (the
    nearest row) and the fractional row of the nearest point: a target between two
    rows is not charged the chord's sampling, and its place along the cycle moves
    continuously with the design."""
    count = traced.shape[0]
    best, place = distance(traced[row], goal, "path"), row.astype(jnp.float64)
    for side in (-1, 1):
        other = (row + side) % count if cyclic else jnp.clip(row + side, 0, count - 1)
        span = traced[other] - traced[row]
        length = jnp.sum(span * span)
        t = jnp.clip(jnp.dot(goal - traced[row], span) / (length + 1e-300), 0.0, 1.0)
        gap = jnp.sqrt(jnp.sum((traced[row] + t * span - goal) ** 2) + 1e-300)
        better = solved[other] & (other != row) & (gap < best)
        best = jnp.where(better, gap, best)
        place = jnp.where(better, row + side * t, place)
    return best, place


def descents(places, cyclic: bool, count: int):
    """Sum of squared descents of the targets' places (fractions of the cycle),
    the better of the two senses: zero when the targets are met in order."""
    if cyclic:
        ahead = jnp.mod(places - places[0], count)
        behind = jnp.mod(places[0] - places, count)
    else:
        ahead, behind = places, -places
    down = [jnp.maximum(seq[:-1] - seq[1:], 0.0) for seq in (ahead, behind)]
    return jnp.minimum(*[jnp.sum((d / count) ** 2) for d in down])


def _transmission(mech, geom, states, solved, four: tuple, need):
    """The transmission penalty and the least transmission angle (rad) over the
    solved rows of a planar four-bar: ``μ`` at ``C`` between ``C → B`` and
    ``C → D``, its distance from a straight line ``asin |sin μ|``."""
    if not four:  # static
        return jnp.zeros(()), jnp.asarray(jnp.pi / 2)
    b, c, d = four

    def worst(state):
        x = homogenised_joint_positions(mech, geom, state)
        u, v = x[b] - x[c], x[d] - x[c]
        sine = jnp.linalg.norm(jnp.cross(u, v)) / (
            jnp.linalg.norm(u) * jnp.linalg.norm(v) + 1e-300
        )
        return jnp.arcsin(jnp.clip(sine, 0.0, 1.0))

    angles = jax.vmap(worst)(states)
    short = jnp.where(solved, jnp.maximum(need - angles, 0.0), 0.0)
    least = jnp.min(jnp.where(solved, angles, jnp.pi / 2))
    return TRANSMISSION_WEIGHT * jnp.mean(short**2), least


def _one(mech, design, states, solved, sigmas, goals, at, limits, static):
    """One design's score parts from its swept states (module docstring);
    ``limits`` ``(α₋, μ_req)``."""
    kind, index, stride, timed, cyclic, four = static
    alpha, need = limits[0], limits[1]
    geom = geometry(mech, design)
    traced = jax.vmap(lambda s: quantity(mech, geom, s, kind, index))(states)
    gaps = jax.vmap(lambda g: jax.vmap(lambda t: distance(t, g, kind))(traced))(
        goals
    )  # (k, S)
    gaps = jnp.where(solved[None], gaps, jnp.inf)
    rows_at = at if timed else jnp.argmin(gaps, axis=1)
    picked = jnp.take_along_axis(gaps, rows_at[:, None], axis=1)[:, 0]
    places = rows_at.astype(jnp.float64)
    if kind == "path" and not timed:  # static
        picked, places = jax.vmap(
            lambda g, r: _to_segments(traced, g, r, solved, cyclic)
        )(goals, rows_at)
        picked = jnp.where(solved[rows_at], picked, jnp.inf)
    finite = jnp.where(jnp.isfinite(picked), picked, 10.0)
    f_sing = 2.0 / sigmas
    culled_sing = jnp.where(solved, culled(f_sing, thresholds(alpha)), 0.0)
    sampled, live = states[::stride], solved[::stride]
    collision = jnp.zeros(())
    if has_collision(mech):  # static
        values = jax.vmap(lambda s: collision_value(mech, geom, s))(sampled)
        collision = mech.collision.weight * jnp.mean(jnp.where(live, values, 0.0))
    order = jnp.zeros(())
    if not timed and goals.shape[0] > 1:  # static
        order = ORDER_WEIGHT * descents(places, cyclic, states.shape[0])
    transmission, least = _transmission(mech, geom, states, solved, four, need)
    parts = {
        "path": 0.5 * jnp.mean(finite**2),
        "singularity": jnp.mean(culled_sing),
        "failure": FAILURE_WEIGHT * jnp.mean((~solved).astype(jnp.float64)),
        "collision": collision,
        "order": order,
        "transmission": transmission,
    }
    scale = to_file(mech, kind, index)
    return {
        **parts,
        "total": sum(parts.values()),
        "distances": picked * (mech.length_scale if kind != "function" else scale[0]),
        "rows": rows_at,
        "solved": solved,
        "least_sigma": jnp.min(jnp.where(solved, sigmas, jnp.inf)),
        "traced": traced * scale,
        "states": states,
        "worst": jnp.argmax(jnp.where(solved, f_sing, -jnp.inf)),
        "least_transmission": least,
    }


def _score_batch(mech, designs, rows, goals, at, limits, static):
    geoms = jax.vmap(lambda p: geometry(mech, p))(designs)
    states, solved, sigmas = sweep(mech, geoms, rows)
    parts = jax.vmap(
        lambda p, s, ok, sg: _one(mech, p, s, ok, sg, goals, at, limits, static)
    )(designs, states, solved, sigmas)
    return Score(**parts)


@dataclass(frozen=True)
class Problem:
    """What a synthesis run scores: the targets and the sweep's plan, with the traced
    quantity's kind and index."""

    targets: Targets
    plan: Plan

    def static(self, mech: Mechanism) -> tuple:
        kind, index = _static(self.targets, mech)
        timed = self.plan.at is not None
        four, _ = four_bar_transmission(mech, self.targets)
        return kind, index, self.plan.stride, timed, self.plan.cyclic, four

    def need(self, mech: Mechanism) -> float:
        """The transmission bound (rad; 0: none)."""
        return four_bar_transmission(mech, self.targets)[1]

    def arguments(self, mech: Mechanism) -> tuple:
        """The homogenised motor rows, targets and target rows."""
        kind, index = _static(self.targets, mech)
        rows = self.plan.motors / np.asarray(mech.motor_scale)
        values = self.targets.values.reshape(self.targets.count, -1)
        goals = values / np.asarray(to_file(mech, kind, index))
        at = np.zeros(self.targets.count, int) if self.plan.at is None else self.plan.at
        return rows, goals, at.astype(np.int32)


def four_bar_transmission(mech: Mechanism, targets: Targets) -> tuple[tuple, float]:
    """The joints ``(B, C, D)`` whose transmission angle a planar four-bar's score
    bounds, and the bound (rad): ``((), 0.0)`` where the mechanism is not a planar
    four-bar or the targets ask none (``min_transmission_deg`` 0)."""
    from .fourbar import four_bar_joints

    need = float(getattr(targets, "min_transmission_deg", 0.0))
    if need <= 0.0:
        return (), 0.0
    try:
        joints = four_bar_joints(mech)
    except InputError:
        return (), 0.0
    return (joints.B, joints.C, joints.D), float(np.radians(need))


def _name(base: str, static: tuple) -> str:
    flat = [
        v for item in static for v in (item if isinstance(item, tuple) else (item,))
    ]
    return f"{base}_" + "_".join(
        f"{v:.6g}" if isinstance(v, float) else str(v) for v in flat
    )


def score(mech: Mechanism, problem: Problem, designs, alpha: float) -> Score:
    """The scores of designs ``(D, n_p)`` (file units)."""
    static = problem.static(mech)
    rows, goals, at = problem.arguments(mech)

    def fn(m, p, r, g, a, al):
        return _score_batch(m, p, r, g, a, al, static)

    return programs.call(
        _name("synthesis_score", static),
        mech,
        fn,
        padded_design(mech, np.asarray(designs, dtype=float)),
        rows,
        goals,
        at,
        jnp.asarray([alpha, problem.need(mech)], dtype=jnp.float64),
    )


def _lagrangian(mech, design, frozen, goals, alpha, static, samples: int):
    """Scalar whose design gradient is the partial gradient of one design's ``path +
    singularity`` (module docstring)."""
    kind, index = static[:2]
    motors, states, worst_motors, worst_state = frozen

    def path_term(goal):
        def term(state, geom):
            d = distance(quantity(mech, geom, state, kind, index), goal, kind)
            return 0.5 * d * d / goals.shape[0]

        return term

    def sing_term(state, geom):
        f = 2.0 / forward_sigma(mech, geom, state)
        return culled(f, thresholds(alpha)) / samples

    path = jax.vmap(lambda g, a, s: adjoint_term(mech, path_term(g), design, a, s))(
        goals, motors, states
    )
    return jnp.sum(path) + adjoint_term(
        mech, sing_term, design, worst_motors, worst_state
    )


def gradients(
    mech: Mechanism, problem: Problem, designs, result: Score, alpha: float
) -> np.ndarray:
    """Partial gradients ``(D, n_p)`` of ``path + singularity`` (file units per unit
    of each parameter) at designs scored as ``result``."""
    static = problem.static(mech)
    rows, goals, _ = problem.arguments(mech)
    d = np.arange(len(designs))[:, None]
    picked = np.asarray(result.rows)
    worst = np.asarray(result.worst)
    frozen = (
        rows[picked],
        np.asarray(result.states)[d, picked],
        rows[worst],
        np.asarray(result.states)[np.arange(len(designs)), worst],
    )
    samples = problem.plan.steps

    def fn(m, p, fr, g, al):
        grad = jax.grad(lambda q, f: _lagrangian(m, q, f, g, al, static, samples))
        return jax.vmap(grad, in_axes=(0, (0, 0, 0, 0)))(p, fr)

    out = programs.call(
        _name("synthesis_gradient", static),
        mech,
        fn,
        padded_design(mech, np.asarray(designs, dtype=float)),
        frozen,
        goals,
        jnp.asarray(alpha, dtype=jnp.float64),
    )
    return np.asarray(out)[:, : mech.design.size]
