"""Joint elimination (paper 000, Sec. V, Algorithm 1) and the optimise → eliminate loop.

For a candidate ``k`` (the segment between joints ``k`` and ``k+1``, 0-based) the
modules between the two joints are replaced by one abstract ``segment`` module, a free
transform ``Trans(x, y, z) Rot_z(yaw) Rot_y(pitch) Rot_x(roll)`` whose six parameters
``d_j`` start at ``SE3toXYZRPY(T_j)`` (line 1). Each iteration (lines 4-17) stacks the
tool Jacobians of all targets in ``(θ_1 … θ_nT, d', d_j)`` (eq. 12, from the engine's
implicit tangents), asks for ``Δd_j = -α d_j`` and solves
``[Δθ; Δd'] = J_{θ,d'}⁺ (V - J_{d_j} Δd_j)`` with ``V`` the velocity that moves every
tool back to its target (lines 7-10), clamping ``V``, ``Δθ`` and ``Δd'`` and keeping
``d'`` in its bounds. Then joints ``k`` and ``k+1`` are merged (``θ_k + θ_{k+1}``, line
19) and ``δ`` (line 22) measures how far the merged arm's tools are from their targets.

Choices where the paper is terse (stated here as the careful-engineer reading):

* The velocity is expressed as ``[ṗ_tool; ω]`` rather than the spatial twist
  ``[ṗ - ω × p; ω]``: the two are related by an invertible map, but the tool-point form
  does not weigh rotations by the distance to the world origin. Angular rows are kept
  only where the target constrains them: none for position-only targets, the part ⟂
  ``n̂_T`` for tip-axis targets (a rotation about the tip axis is free), all three for
  full orientations, whose error is ``ω = ½ Σ_c (R_fk e_c) × (R_T e_c)``.
* Step clamps (Sec. V-B): ``|V|`` 0.5 (linear) / 0.05 (angular), ``|Δd'|`` 0.1 / 0.01,
  ``|Δθ|`` 0.05 rad; ``α = 10⁻²``, 500 iterations; the loop also stops when
  ``|d_j| < 10⁻⁴``.
* One compiled pose program for every step (:func:`pad`): each candidate's segment
  arm and each merged arm is written over the *root* arm (the task's) as traced data, a
  :class:`~linkopt._arms.codesign.model.Layout` (which non-joint modules are kept,
  which joint the free segment follows); dropped joints are held at θ = 0 and their
  Jacobian columns cut. An arm per structure as a static argument compiled the pose
  program again for every candidate and every merged arm (12 programs for the square
  task's 4 → 1 joints). Measured on ``linkopt arm simplify
  tasks/elimination_square.toml``, shared 2-core machine, per-arm programs then this,
  one after the other (load 3.5-4.8): cold cache 101 → 85 XLA programs, 5:55 → 3:09
  wall, 298 → 218 s CPU; warm cache 1:52 → 1:33 wall, 108 → 90 s CPU (the pose
  program on the root's larger Jacobians costs no visible time per step). The pose
  programs' compilation alone, from ``JAX_LOG_COMPILES``: 12 programs, 130 s → 1, 27 s.
* Algorithm 1 on that task is sensitive to rounding: a 10⁻¹³ change of the start
  configurations moves candidate 3's δ from 0.49 to 4·10⁻⁵ (500 pseudo-inverse steps
  with ``rcond = 10⁻⁸`` on a rank-deficient stack), so the padded program, equal to the
  per-arm one to rounding (tested), may pick another candidate there.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ..._config import jit
from ..._engine import rotations as rot
from . import multistart, nlp
from .model import (
    Arm,
    Layout,
    Lineage,
    Module,
    compose,
    make_arm,
    module_transform,
    tool_pose,
)

ANGLE_SLOTS = ("roll", "pitch", "yaw")


@dataclass(frozen=True)
class EliminationSettings:
    """Algorithm 1's constants (module docstring; paper Sec. V-B)."""

    alpha: float = 1e-2
    iterations: int = 500
    threshold: float = 1e-4
    clamp_velocity: tuple[float, float] = (0.5, 0.05)  # linear, angular
    clamp_design: tuple[float, float] = (0.1, 0.01)
    clamp_theta: float = 0.05


@dataclass(frozen=True)
class Elimination:
    """Result of Algorithm 1 for one candidate: the merged arm, its ``θ'`` at the
    targets ``(n_T, n-1)``, its design ``d'`` and the error ``δ``; ``segment`` is
    ``|d_j|`` at the end."""

    candidate: int
    arm: Arm
    theta: np.ndarray
    design: np.ndarray
    delta: float
    segment: float
    iterations: int


def _between(arm: Arm, k: int) -> range:
    joints = arm.joint_modules
    return range(int(joints[k]) + 1, int(joints[k + 1]))


def _rebuild(
    arm: Arm,
    modules: list[Module],
    keep: np.ndarray,
    extra: list[tuple[str, float, float, float, bool]],
    name: str,
) -> Arm:
    """An arm of ``modules`` whose design is ``d[keep]`` followed by ``extra``
    variables."""
    remap = {int(old): new for new, old in enumerate(keep)}
    fixed = [
        Module(
            m.kind,
            tuple((remap.get(i, -1) if i >= 0 else -1, v) for i, v in m.slots),
            m.mass,
        )
        if m.kind != "segment"
        else m
        for m in modules
    ]
    names = [arm.design_names[i] for i in keep] + [e[0] for e in extra]
    d0 = np.concatenate([arm.d0[keep], [e[1] for e in extra]])
    lower = np.concatenate([arm.lower[keep], [e[2] for e in extra]])
    upper = np.concatenate([arm.upper[keep], [e[3] for e in extra]])
    is_length = np.concatenate([arm.is_length[keep], [e[4] for e in extra]]).astype(
        bool
    )
    return make_arm(
        name,
        tuple(fixed),
        names,
        d0,
        lower,
        upper,
        is_length,
        arm.torque_limit,
        arm.radius,
        arm.mechanism.source,
    )


def _kept(arm: Arm, inside: range) -> np.ndarray:
    """Indices of the design variables no module in ``inside`` reads."""
    used = {i for m in (arm.modules[i] for i in inside) for i, _ in m.slots if i >= 0}
    return np.array([i for i in range(arm.num_design) if i not in used], dtype=int)


def _segment_design(arm: Arm, k: int, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``keep`` (the indices of ``d'`` in ``d``) and ``d_j = SE3toXYZRPY(T_j)`` of
    candidate ``k``."""
    inside = _between(arm, k)
    frame = (jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.zeros(3))
    for i in inside:
        frame = compose(frame, module_transform(arm.modules[i], jnp.asarray(d)))
    d_j = np.concatenate(
        [np.asarray(frame[1]), rot.np_rpy(np.asarray(rot.matrix(frame[0])))]
    )
    return _kept(arm, inside), d_j


def segment_arm(arm: Arm, k: int, d: np.ndarray) -> tuple[Arm, np.ndarray, np.ndarray]:
    """The arm with the modules between joints ``k`` and ``k+1`` replaced by a free
    segment; returns it, the indices ``keep`` of ``d'`` in ``d``, and
    ``d_j = SE3toXYZRPY(T_j)``. (:func:`eliminate` works on :func:`pad`'s form of the
    same arm, which needs no new program.)"""
    inside = _between(arm, k)
    keep, d_j = _segment_design(arm, k, d)
    m_prime = keep.size
    slots = tuple((m_prime + s, 0.0) for s in range(6))
    modules = (
        list(arm.modules[: inside.start])
        + [Module("segment", slots, sum(arm.modules[i].mass for i in inside))]
        + list(arm.modules[inside.stop :])
    )
    extra = [
        (f"segment{k + 1}.{s}", 0.0, -1e3, 1e3, s not in ANGLE_SLOTS)
        for s in ("x", "y", "z", "roll", "pitch", "yaw")
    ]
    return _rebuild(arm, modules, keep, extra, arm.name), keep, d_j


def merged_arm(arm: Arm, k: int, keep: np.ndarray) -> Arm:
    """The arm with the modules between joints ``k`` and ``k+1`` and joint ``k+1``
    removed."""
    inside = _between(arm, k)
    modules = list(arm.modules[: inside.start]) + list(arm.modules[inside.stop + 1 :])
    merged = _rebuild(
        arm, modules, keep, [], f"{arm.name.split(',')[0]}, {arm.num_joints - 1} joints"
    )
    line = lineage(arm)
    places = np.concatenate(
        [line.modules[: inside.start], line.modules[inside.stop + 1 :]]
    )
    return replace(merged, lineage=Lineage(line.root, places, line.design[keep]))


def lineage(arm: Arm) -> Lineage:
    """``arm``'s place in the arm it was reduced from (itself for a task's arm)."""
    if arm.lineage is not None:
        return arm.lineage
    return Lineage(arm, np.arange(len(arm.modules)), np.arange(arm.num_design))


@dataclass(frozen=True)
class Padded:
    """A reduced arm (``candidate``: with that segment free) written over its root
    arm's modules (:class:`~linkopt._arms.codesign.model.Layout`): the root's
    ``θ`` columns of its joints ``(n,)`` and the ``[d_root, segment]`` columns of its
    design variables (``(m,)``, then the segment's six)."""

    root: Arm
    layout: Layout
    joints: np.ndarray  # (n,)
    design: np.ndarray  # (m,) or (m' + 6,)
    base: np.ndarray = field(repr=False)  # (m_root + 6,) values of unused columns

    def theta(self, theta: np.ndarray) -> np.ndarray:
        """``θ`` rows ``(..., n)`` as the root's ``(..., n_root)``, dropped joints 0."""
        full = np.zeros(theta.shape[:-1] + (self.root.num_joints,))
        full[..., self.joints] = theta
        return full

    def d(self, d: np.ndarray) -> np.ndarray:
        """The arm's design ``(len(design),)`` as ``[d_root, segment]``."""
        full = self.base.copy()
        full[self.design] = d
        return full


def pad(arm: Arm, d: np.ndarray, candidate: int | None = None) -> Padded:
    """``arm`` over its root's modules; with a ``candidate`` ``k`` the modules between
    joints ``k`` and ``k+1`` are dropped and the free segment follows joint ``k``.

    ``d`` (the arm's design) fills the root columns the result does not expose: the
    variables of the dropped modules, whose transforms are masked out. (A task file
    gives every slot its own variable, so no kept module reads them.)
    """
    line = lineage(arm)
    root = line.root
    present = np.zeros(len(root.modules), dtype=bool)
    present[line.modules] = True
    segment = np.zeros(len(root.modules), dtype=bool)
    design = line.design
    if candidate is not None:
        inside = _between(arm, candidate)
        present[line.modules[inside.start : inside.stop]] = False
        segment[line.modules[arm.joint_modules[candidate]]] = True
        keep = _kept(arm, inside)
        m = root.num_design
        design = np.concatenate([line.design[keep], np.arange(m, m + 6)])
    base = np.concatenate([root.d0, np.zeros(6)])
    base[line.design] = np.asarray(d, float)
    joints = np.searchsorted(root.joint_modules, line.modules[arm.joint_modules])
    return Padded(root, Layout(present, segment), joints, design, base)


@partial(jit, static_argnums=0)
def root_poses(root: Arm, layout: Layout, theta, d):
    """Tool positions ``(n_T, 3)``, rotations ``(n_T, 3, 3)`` and the eq. 12 blocks
    ``[ṗ; ω]`` per target: ``(n_T, 6, n)`` in θ and ``(n_T, 6, m)`` in d, of the arm
    ``layout`` describes on ``root`` (compiled once per root arm and target count)."""

    def pose(th, dd):
        tip, rot, _, _ = tool_pose(root, th, dd, layout)
        return tip, rot

    def blocks(th, dd):
        (tip, rot), (dp, dr) = pose(th, dd), jax.jacfwd(pose, argnums=(0, 1))(th, dd)

        def twist(dp_x, dr_x):  # (3, k), (3, 3, k) -> (6, k)
            w = jnp.einsum("abk,cb->ack", dr_x, rot)
            return jnp.concatenate(
                [dp_x, jnp.stack([w[2, 1], w[0, 2], w[1, 0]])], axis=0
            )

        return tip, rot, twist(dp[0], dr[0]), twist(dp[1], dr[1])

    return jax.vmap(blocks, in_axes=(0, None))(theta, d)


def poses(padded: Padded, theta: np.ndarray, d: np.ndarray):
    """:func:`root_poses` of the padded arm, Jacobians cut to its ``(θ, d)`` columns
    (numpy)."""
    tip, rot, j_theta, j_d = (
        np.asarray(a)
        for a in root_poses(
            padded.root,
            Layout(*(jnp.asarray(a) for a in padded.layout)),
            jnp.asarray(padded.theta(np.asarray(theta, float))),
            jnp.asarray(padded.d(np.asarray(d, float))),
        )
    )
    return tip, rot, j_theta[..., padded.joints], j_d[..., padded.design]


def _target_velocity(problem: nlp.Problem, tip, rot, settings: EliminationSettings):
    """Clamped ``V`` (lines 7-10) and the row projection of every target
    ``(n_T, 6, 6)``."""
    dp = problem.target_position - tip
    lin, ang = settings.clamp_velocity
    dp = dp * np.minimum(
        1.0, lin / np.maximum(np.linalg.norm(dp, axis=1, keepdims=True), 1e-300)
    )
    omega = np.zeros_like(dp)
    proj = np.zeros((len(dp), 6, 6))
    proj[:, :3, :3] = np.eye(3)
    for i, rows in enumerate(problem.rows):
        n_t = problem.target_axis[i]
        if rows[2]:
            goal = problem.target_rotation[i]
            omega[i] = 0.5 * np.sum(np.cross(rot[i].T, goal.T), axis=0)
            proj[i, 3:, 3:] = np.eye(3)
        elif rows[1]:
            omega[i] = np.cross(rot[i][:, 2], n_t)
            proj[i, 3:, 3:] = np.eye(3) - np.outer(n_t, n_t)
    omega = omega * np.minimum(
        1.0, ang / np.maximum(np.linalg.norm(omega, axis=1, keepdims=True), 1e-300)
    )
    return np.concatenate([dp, omega], axis=1), proj


def _clamp(step: np.ndarray, limits: np.ndarray) -> np.ndarray:
    return np.clip(step, -limits, limits)


def delta_error(
    problem: nlp.Problem, arm: Arm, theta: np.ndarray, d: np.ndarray
) -> float:
    """``δ = Σ |p_T - p_fk|² + (1 - n̂_fk · n̂_T)`` over the targets (line 22; the tip
    term only where a tip axis is given)."""
    tip, rot, _, _ = poses(pad(arm, d), theta, d)
    position = np.sum((problem.target_position - tip) ** 2)
    axis = np.sum(
        problem.rows[:, 1] * (1.0 - np.sum(rot[:, :, 2] * problem.target_axis, axis=1))
    )
    return float(position + axis)


def eliminate(
    problem: nlp.Problem,
    theta_targets: np.ndarray,
    d: np.ndarray,
    k: int,
    settings: EliminationSettings = EliminationSettings(),
) -> Elimination:
    """Algorithm 1 for candidate ``k`` from the configurations at the targets
    ``(n_T, n)``."""
    arm = problem.arm
    keep, d_j = _segment_design(arm, k, d)
    padded = pad(arm, d, k)
    d_prime = np.asarray(d, float)[keep].copy()
    theta = np.asarray(theta_targets, float).copy()
    n_t, n = theta.shape
    lin_d = np.where(
        arm.is_length[keep], settings.clamp_design[0], settings.clamp_design[1]
    )
    iteration = 0
    while iteration < settings.iterations and np.linalg.norm(d_j) > settings.threshold:
        tip, rot, j_theta, j_d = poses(padded, theta, np.concatenate([d_prime, d_j]))
        v, proj = _target_velocity(problem, tip, rot, settings)
        stack = np.zeros((n_t, 6, n_t * n + keep.size))
        for i in range(n_t):
            stack[i, :, i * n : (i + 1) * n] = proj[i] @ j_theta[i]
            stack[i, :, n_t * n :] = proj[i] @ j_d[i, :, : keep.size]
        j_dj = np.einsum("iab,ibk->iak", proj, j_d[:, :, keep.size :]).reshape(-1, 6)
        step_j = -settings.alpha * d_j
        rhs = np.einsum("iab,ib->ia", proj, v).ravel() - j_dj @ step_j
        step = np.linalg.pinv(stack.reshape(n_t * 6, -1), rcond=1e-8) @ rhs
        theta += _clamp(
            step[: n_t * n].reshape(n_t, n), np.full(n, settings.clamp_theta)
        )
        d_prime = np.clip(
            d_prime + _clamp(step[n_t * n :], lin_d), arm.lower[keep], arm.upper[keep]
        )
        d_j = d_j + step_j
        iteration += 1
    merged = merged_arm(arm, k, keep)
    theta_merged = merge_trajectory(theta, k)
    reduced = replace(problem, arm=merged)
    return Elimination(
        k,
        merged,
        theta_merged,
        d_prime,
        delta_error(reduced, merged, theta_merged, d_prime),
        float(np.linalg.norm(d_j)),
        iteration,
    )


def merge_trajectory(theta: np.ndarray, k: int) -> np.ndarray:
    """Waypoint configurations ``(n_W, n)`` with joints ``k`` and ``k+1`` merged (line
    19)."""
    merged = np.delete(theta, k + 1, axis=1)
    merged[:, k] += theta[:, k + 1]
    return merged


def best_elimination(
    problem: nlp.Problem,
    solution: multistart.ArmSolution,
    settings: EliminationSettings = EliminationSettings(),
) -> tuple[Elimination, list[Elimination]]:
    """Algorithm 1 for every candidate joint pair; the one of least ``δ`` first."""
    at = problem.target_waypoints
    runs = [
        eliminate(problem, solution.theta[at], solution.design, k, settings)
        for k in range(problem.arm.num_joints - 1)
    ]
    return min(runs, key=lambda e: e.delta), runs


def reoptimise(
    problem: nlp.Problem,
    solution: multistart.ArmSolution,
    elimination: Elimination,
    max_iterations: int | None = None,
) -> tuple[nlp.Problem, multistart.ArmSolution]:
    """Re-solve eq. 1 for the merged arm from ``(θ', d')`` (intermediate waypoints
    merged from the previous solution), which corrects Algorithm 1's drift."""
    reduced = nlp.prepare(problem.task, elimination.arm)
    theta = merge_trajectory(solution.theta, elimination.candidate)
    theta[problem.target_waypoints] = elimination.theta
    z0 = np.concatenate([theta.ravel(), elimination.design])
    return reduced, multistart.solve_from(reduced, z0, max_iterations=max_iterations)


@dataclass(frozen=True)
class Stage:
    """One stage of the simplification loop: the problem, its solution, the elimination
    that produced it (None for the first) and the candidates' ``δ``."""

    problem: nlp.Problem
    solution: multistart.ArmSolution
    elimination: Elimination | None
    deltas: tuple[float, ...] = ()


def simplify(
    problem: nlp.Problem,
    first: multistart.ArmSolution,
    *,
    min_joints: int = 1,
    settings: EliminationSettings = EliminationSettings(),
    progress=None,
) -> list[Stage]:
    """Alternate Algorithm 1 and re-optimisation from a solved ``first`` stage while the
    re-optimised arm stays feasible and has more than ``min_joints`` joints."""
    stages = [Stage(problem, first, None)]
    while stages[-1].problem.arm.num_joints > max(min_joints, 1):
        current = stages[-1]
        best, runs = best_elimination(current.problem, current.solution, settings)
        reduced, solution = reoptimise(current.problem, current.solution, best)
        stages.append(Stage(reduced, solution, best, tuple(r.delta for r in runs)))
        if progress:
            progress(stages[-1])
        if not solution.feasible:
            break
    return stages
