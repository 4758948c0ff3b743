"""Dense verification of the continuous motion of a synthesised arm (paper 002,
Sec. III-E, III-F).

Along every primitive the joint angles come from the closed-form IK on the design's
elbow branch (the proximal link of a 3-link arm is static); along every transition of a
3-link arm the proximal angle ``θ_1`` moves linearly from its value on one primitive to
its value on the next while the end-effector stays at the transition point (the
four-bar of Sec. III-F-2b), the distal pair following by IK. At every sample we check:

* reachability (eq. 2) of the end-effector from ``s_{n-1}``;
* link-to-obstacle clearance: distance from each obstacle centre to each link segment at
  least ``r_o + Δ/2 + δ/2``, where ``δ`` is the largest displacement of that link's end
  points to a neighbouring sample (a first-order bound on what the motion between
  samples can add); samples are spaced Δ/16 along the path;
* self-collision: the end-effector farther than Δ from every link it is not attached to
  (eqs. 8-9);
* continuity: no joint moves more than ``MAX_JOINT_STEP`` between samples.

A design is reported by synthesis only if :func:`verify` passes.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import numpy as np
from jaxtyping import Float

from ... import _config  # noqa: F401  (float64 on before any array)
from . import geometry as geo
from .task import TraceTask

MAX_JOINT_STEP = 0.25
MIN_SAMPLES = 200
MAX_SAMPLES = 200_000


@dataclass(frozen=True)
class PlanarArm:
    """A planar arm: base ``s_1``, link lengths ``r`` (2 or 3), the static proximal
    angle per primitive (3 links; absolute, from the x-axis) and the elbow branch."""

    base: Float[np.ndarray, 2]
    lengths: Float[np.ndarray, " n"]
    proximal_angles: Float[np.ndarray, " q"]
    sigma: int

    @property
    def n_links(self) -> int:
        return int(len(self.lengths))


@dataclass(frozen=True)
class Segment:
    """Dense states of one primitive (``kind="primitive"``) or transition."""

    kind: str
    index: int
    states: Float[np.ndarray, "N n+1 2"]
    angles: Float[np.ndarray, "N n"]


@dataclass(frozen=True)
class TraceVerification:
    passed: bool
    failures: tuple[str, ...]
    min_clearance: float
    min_self_distance: float
    min_reach_margin: float
    max_joint_step: float
    segments: tuple[Segment, ...] = ()


def _proximal(design: PlanarArm, j: int) -> float:
    return float(design.proximal_angles[j]) if design.n_links == 3 else 0.0


def primitive_states(
    task: TraceTask, design: PlanarArm, j: int, t: np.ndarray
) -> np.ndarray:
    """``(N, n_links+1, 2)`` states along primitive ``j`` at path parameters ``t``."""
    p = geo.points(task.primitives[j], np.asarray(t))
    return np.asarray(
        geo.arm_states(
            design.base,
            np.asarray(design.lengths),
            _proximal(design, j),
            p,
            design.sigma,
        )
    )


def transition_states(
    task: TraceTask, design: PlanarArm, j: int, tau: np.ndarray
) -> np.ndarray:
    """States of the transition from primitive ``j`` to ``j+1`` at fractions ``tau``:
    the end-effector stays at the transition point, ``θ_1`` moves linearly (3 links);
    a 2-link arm has no transition motion (mobility 0), its state is repeated."""
    theta = _proximal(design, j) + np.asarray(tau, dtype=float) * (
        _proximal(design, j + 1) - _proximal(design, j)
    )
    # one row per angle: the proximal link's end and the end-effector's point per row
    point = np.broadcast_to(task.primitives[j].end, theta.shape + (2,))
    lengths = np.asarray(design.lengths, dtype=float)
    return geo.arm_states(design.base, lengths, theta, point, design.sigma)


def dense_states(fn, n: int, target: float) -> tuple[np.ndarray, np.ndarray]:
    """Sample ``fn(t)`` on ``n`` even ``t`` in [0, 1], then split every interval in
    which a joint moves more than ``target`` (two passes, at most ``MAX_SAMPLES``)."""
    t = np.linspace(0.0, 1.0, n)
    states = fn(t)
    for _ in range(2):
        move = np.linalg.norm(np.diff(states, axis=0), axis=2).max(axis=1)
        k = np.maximum(1, np.ceil(move / target)).astype(int)
        if k.max() == 1 or k.sum() > MAX_SAMPLES:
            break
        offsets = np.arange(k.sum()) - np.repeat(np.cumsum(k) - k, k)
        t = np.append(
            np.repeat(t[:-1], k) + offsets / np.repeat(k, k) * np.repeat(np.diff(t), k),
            1.0,
        )
        states = fn(t)
    return t, states


def critical_states(task: TraceTask, design: PlanarArm) -> list[np.ndarray]:
    """States at (initial, final, closest, farthest) of every primitive, ``(4, n+1, 2)``
    each."""
    out = []
    lengths = np.asarray(design.lengths)
    for j, prim in enumerate(task.primitives):
        origin = geo.distal_origin(design.base, lengths, _proximal(design, j))
        cp = geo.critical_points(prim, origin)
        pts = np.stack([cp[k] for k in ("initial", "final", "closest", "farthest")])
        out.append(
            np.asarray(
                geo.arm_states(
                    design.base, lengths, _proximal(design, j), pts, design.sigma
                )
            )
        )
    return out


def _sample_count(length: float, task: TraceTask) -> int:
    return int(max(MIN_SAMPLES, np.ceil(length / (task.link_diameter / 16))))


def _reach_margin(task: TraceTask, design: PlanarArm, states: np.ndarray) -> np.ndarray:
    a, b = design.lengths[-2:]
    d = np.linalg.norm(states[:, -1] - states[:, -3], axis=1)
    return np.minimum(a + b - d, d - abs(a - b))


def _motion_bound(states: np.ndarray) -> np.ndarray:
    """``(N, links)``: half the largest move of a link's end points to a neighbouring
    sample; to first order no point of the link gets farther than this from where it
    is at a sample while moving to its neighbours."""
    if len(states) < 2:
        return np.zeros((len(states), states.shape[1] - 1))
    move = np.linalg.norm(np.diff(states, axis=0), axis=2)
    link = np.maximum(move[:, :-1], move[:, 1:])
    padded = np.concatenate([link[:1], link, link[-1:]])
    return 0.5 * np.maximum(padded[:-1], padded[1:])


def _clearance(task: TraceTask, states: np.ndarray) -> np.ndarray:
    """``(N, links, n_obs)`` distance of link segments to obstacle discs minus Δ/2 and
    minus the motion bound between samples."""
    if len(task.obstacles) == 0:
        return np.full((len(states), states.shape[1] - 1, 0), np.inf)
    c = task.obstacles[:, :2][None, None]
    a, b = states[:, :-1, None], states[:, 1:, None]
    d = np.asarray(geo.segment_distance(np.asarray(c), np.asarray(a), np.asarray(b)))
    return (
        d
        - task.obstacles[:, 2]
        - task.link_diameter / 2
        - _motion_bound(states)[:, :, None]
    )


def _self_distance(states: np.ndarray) -> np.ndarray:
    """End-effector to every link but the last (eqs. 8-9), ``(N, links-1)``."""
    ee = np.asarray(states[:, -1:])
    return np.asarray(
        geo.segment_distance(
            ee, np.asarray(states[:, :-2]), np.asarray(states[:, 1:-1])
        )
    )


def _check(
    task: TraceTask,
    design: PlanarArm,
    label: str,
    states: np.ndarray,
    failures: list[str],
) -> dict:
    clear = _clearance(task, states)
    selfd = _self_distance(states) - task.link_diameter
    reach = _reach_margin(task, design, states)
    angles = np.asarray(geo.joint_angles(np.asarray(states)))
    jstep = (
        np.abs(np.angle(np.exp(1j * np.diff(angles, axis=0)))).max()
        if len(states) > 1
        else 0.0
    )
    tol = 1e-9 * task.scale
    if reach.min() < -tol:
        k = int(reach.argmin())
        failures.append(
            f"{label}: end-effector outside the reachable annulus (eq. 2) at sample "
            f"{k} by {-reach[k]:.3g}"
        )
    if clear.size and clear.min() < 0:
        k, link, o = np.unravel_index(clear.argmin(), clear.shape)
        failures.append(
            f"{label}: link {link + 1} clips obstacles[{o}] at sample {k} "
            f"(clearance {clear.min():.3g})"
        )
    if selfd.size and selfd.min() < 0:
        failures.append(
            f"{label}: end-effector within Δ of another link (eqs. 8-9), margin "
            f"{selfd.min():.3g}"
        )
    if jstep > MAX_JOINT_STEP:
        failures.append(
            f"{label}: a joint jumps {jstep:.3g} rad between samples (motion not "
            "continuous)"
        )
    return {
        "clear": clear.min() if clear.size else np.inf,
        "self": selfd.min() if selfd.size else np.inf,
        "reach": reach.min(),
        "jstep": jstep,
        "angles": angles,
    }


def verify(task: TraceTask, design: PlanarArm) -> TraceVerification:
    """Check the whole continuous task (every primitive and transition) densely: ``t``
    spaced Δ/16 along the path, refined until no joint moves more than Δ/32."""
    failures: list[str] = []
    segments, stats = [], []
    q, target = len(task.primitives), task.link_diameter / 32
    for j, prim in enumerate(task.primitives):
        fn = partial(primitive_states, task, design, j)
        _, states = dense_states(fn, _sample_count(prim.length, task), target)
        st = _check(task, design, f"primitives[{j}]", states, failures)
        segments.append(Segment("primitive", j, states, st["angles"]))
        stats.append(st)
        if j == q - 1:
            continue
        fn = partial(transition_states, task, design, j)
        _, states = dense_states(fn, MIN_SAMPLES if design.n_links == 3 else 2, target)
        st = _check(task, design, f"transition {j}->{j + 1}", states, failures)
        segments.append(Segment("transition", j, states, st["angles"]))
        stats.append(st)
    return TraceVerification(
        passed=not failures,
        failures=tuple(failures),
        min_clearance=float(min(s["clear"] for s in stats)),
        min_self_distance=float(min(s["self"] for s in stats)),
        min_reach_margin=float(min(s["reach"] for s in stats)),
        max_joint_step=float(max(s["jstep"] for s in stats)),
        segments=tuple(segments),
    )
