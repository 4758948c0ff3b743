"""Design and trajectory together: the constrained NLP of paper 000, eq. 1-8.

Decision variables ``z = [Θ (n_W, n) raveled, d (m,)]``: the joint angles at every
waypoint and the design. Waypoints: ``waypoints_per_target · n_T`` in all (paper: 4
n_T); the first and last are the first and last targets and the ``(k-1) n_T``
intermediate waypoints are shared among the target-to-target segments in proportion to
their lengths (largest remainders, at least one per segment when there are enough).

Objective (eq. 1)
``w_path f_path + w_joints f_joints + w_length f_length + w_τ f_τ + w_obs f_obs``:

* ``f_path = Σ |p_i - p_{i+1}|²`` (eq. 6),
  ``f_joints = Σ Σ_j 1 - cos(θ_ij - θ_{i+1,j})`` (eq. 5);
* ``f_length = Σ`` of the design variables that are link/tool lengths;
* ``f_τ = Σ (τ/τ_max)²`` over joints and waypoints (eq. 8 divided by τ_max²: the paper's
  weights were tuned for N·m of its modules; dividing keeps w_τ = 20 meaningful for any
  torque limit — a choice, since the paper does not say);
* ``f_obs = Σ c(D(x) - r)`` over points spread along every module at every waypoint,
  ``c`` the CHOMP cost of :mod:`linkopt._arms.codesign.sdf`, ``D`` the SDF, ``r`` the
  module radius.

Constraints ``g ≤ 0``: position (eq. 2), tip axis (eq. 3), full orientation (eq. 4) and
the approach cone ``cos(a) - (R_fk e)·a_T`` at targets; torque limits ``±τ - τ_max`` at
every waypoint (eq. 7), with static torques from the constraint multipliers
(:mod:`linkopt._engine.statics`).

Solved by scipy's SLSQP with exact JAX gradients from several random seeds (designs
uniform in their bounds, target configurations uniform in [-π, π], intermediate
waypoints interpolated), keeping the best feasible result. Infeasible seeds are allowed.
The constraint Jacobian is block-sparse (a waypoint's rows depend on its θ and on d), so
it is assembled from per-waypoint ``jacfwd`` blocks, vmapped over the waypoints.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from ..._config import jit
from ..._engine.constraints import homogenised_point_positions
from ..._engine.statics import motor_torques
from .model import Arm, arm_loads, tool_pose
from .sdf import DistanceField, build_field, chomp_cost, field_distance
from .task import Task

SAMPLES_PER_MODULE = 8  # obstacle points along each module
FEASIBLE_TOL = 1e-6  # max g for a feasible solution
OBJECTIVE_SCALE = 1e-3  # SLSQP sees f / 1000: the paper's weights give f ~ 1e3-1e4


def waypoint_layout(targets: np.ndarray, per_target: int) -> np.ndarray:
    """Waypoint index of every target ``(n_T,)``; ``n_W = per_target · n_T`` (module
    docstring)."""
    count = len(targets)
    total = per_target * count
    if count == 1:
        return np.zeros(1, dtype=int)
    lengths = np.linalg.norm(np.diff(targets, axis=0), axis=1) + 1e-12
    spare = total - count
    share = spare * lengths / lengths.sum()
    base = np.floor(share).astype(int)
    if spare >= count - 1:
        base = np.maximum(base, 1)
    while base.sum() > spare:
        base[np.argmax(base - share)] -= 1
    order = np.argsort(-(share - base))
    base[order[: spare - base.sum()]] += 1
    return np.concatenate([[0], np.cumsum(base + 1)])


@dataclass(frozen=True, eq=False)
class Problem:
    """A task prepared for the NLP: static layout, SDF, target arrays (hashed by
    identity)."""

    task: Task
    arm: Arm
    target_waypoints: np.ndarray  # (n_T,)
    num_waypoints: int
    field: DistanceField | None
    target_position: np.ndarray  # (n_T, 3)
    target_axis: np.ndarray  # (n_T, 3), zero where none
    target_rotation: np.ndarray  # (n_T, 3, 3)
    approach: np.ndarray  # (n_T, 7): local (3), world (3), cos limit
    rows: np.ndarray  # (n_T, 4) bool: position, tip, rotation, approach present

    @property
    def size(self) -> int:
        return self.num_waypoints * self.arm.num_joints + self.arm.num_design

    def split(self, z):
        n = self.arm.num_joints
        return z[: self.num_waypoints * n].reshape(self.num_waypoints, n), z[
            self.num_waypoints * n :
        ]


def prepare(task: Task, arm: Arm | None = None) -> Problem:
    """Layout, SDF and target arrays of ``task`` for ``arm`` (default the task's
    arm)."""
    arm = arm or task.arm
    targets = task.targets
    positions = np.array([t.position for t in targets])
    field = None
    if task.obstacles:
        field = build_field(
            task.obstacles,
            task.workspace[0],
            task.workspace[1],
            task.voxel,
            max_cells=task.max_cells,
        )
    axis = np.array([t.axis if t.axis is not None else np.zeros(3) for t in targets])
    rotation = np.array(
        [t.orientation if t.orientation is not None else np.eye(3) for t in targets]
    )
    approach = np.array(
        [
            np.concatenate([t.approach[0], t.approach[1], [t.approach[2]]])
            if t.approach
            else np.zeros(7)
            for t in targets
        ]
    )
    rows = np.array(
        [
            [
                True,
                t.axis is not None,
                t.orientation is not None,
                t.approach is not None,
            ]
            for t in targets
        ]
    )
    layout = waypoint_layout(positions, task.solver["waypoints_per_target"])
    return Problem(
        task,
        arm,
        layout,
        task.solver["waypoints_per_target"] * len(targets),
        field,
        positions,
        axis,
        rotation,
        approach,
        rows,
    )


def _waypoint(problem: Problem, theta, d, loads):
    """Tool pose, static torques and obstacle cost of one waypoint."""
    arm = problem.arm
    tip, rot, geom, state = tool_pose(arm, theta, d)
    tau = motor_torques(arm.mechanism, geom, state, *loads)
    obstacle = jnp.zeros(())
    if problem.field is not None:
        ends = (
            homogenised_point_positions(arm.mechanism, geom, state)[:-1]
            * arm.mechanism.length_scale
        )
        t = jnp.linspace(0.0, 1.0, SAMPLES_PER_MODULE)[None, :, None]
        samples = (ends[:-1, None, :] * (1 - t) + ends[1:, None, :] * t).reshape(-1, 3)
        distance = field_distance(problem.field, samples) - arm.radius
        obstacle = jnp.sum(chomp_cost(distance, problem.task.clearance))
    return tip, rot, tau, obstacle


def _loads(problem: Problem, d):
    task = problem.task
    return arm_loads(problem.arm, d, task.gravity, task.payload)


def _target_rows(problem: Problem, tip, rot, index):
    """``[g_pos, g_tip, g_rot, g_approach]`` of target ``index`` (eq. 2-4,
    Sec. III-E)."""
    tol = problem.task.tolerances
    p_t = jnp.asarray(problem.target_position)[index]
    g_pos = jnp.sum((p_t - tip) ** 2) - tol["position"]
    g_tip = 1.0 - rot[:, 2] @ jnp.asarray(problem.target_axis)[index] - tol["tip"]
    diff = jnp.eye(3) - rot @ jnp.asarray(problem.target_rotation)[index].T
    g_rot = jnp.sqrt(jnp.sum(diff**2) + 1e-300) - tol["rotation"]
    cone = jnp.asarray(problem.approach)[index]
    g_app = cone[6] - (rot @ cone[:3]) @ cone[3:6]
    return jnp.stack([g_pos, g_tip, g_rot, g_app])


def _row_mask(problem: Problem) -> np.ndarray:
    """``(n_W, 4 + 2n)`` mask of the constraint rows that exist."""
    n = problem.arm.num_joints
    mask = np.zeros((problem.num_waypoints, 4 + 2 * n), dtype=bool)
    mask[:, 4:] = True
    mask[problem.target_waypoints, :4] = problem.rows
    return mask


def _target_of_waypoint(problem: Problem) -> np.ndarray:
    index = np.zeros(problem.num_waypoints, dtype=int)
    index[problem.target_waypoints] = np.arange(len(problem.target_waypoints))
    return index


def _outputs(problem: Problem, theta, d):
    """Per-waypoint quantities ``[tip (3), R_fk (9), τ (n), obstacle cost (1)]``."""
    tip, rot, tau, obstacle = _waypoint(problem, theta, d, _loads(problem, d))
    return jnp.concatenate([tip, rot.ravel(), tau, obstacle[None]])


def _unpack(problem: Problem, out):
    n = problem.arm.num_joints
    return (
        out[..., :3],
        out[..., 3:12].reshape(out.shape[:-1] + (3, 3)),
        out[..., 12 : 12 + n],
        out[..., 12 + n],
    )


def _parts(problem: Problem, out, theta, d) -> dict:
    """Unweighted objectives from the per-waypoint outputs (module docstring)."""
    tip, _, tau, obstacle = _unpack(problem, out)
    lengths = np.array(
        [name.endswith(".length") for name in problem.arm.design_names], dtype=bool
    )
    return {
        "path": jnp.sum(jnp.diff(tip, axis=0) ** 2),
        "joints": jnp.sum(1.0 - jnp.cos(jnp.diff(theta, axis=0))),
        "length": jnp.sum(d[lengths]) if lengths.any() else jnp.zeros(()),
        "torque": jnp.sum((tau / problem.arm.torque_limit) ** 2),
        "obstacle": jnp.sum(obstacle),
    }


def _weighted(problem: Problem, out, theta, d):
    parts = _parts(problem, out, theta, d)
    w = problem.task.weights
    return sum(w[k] * v for k, v in parts.items())


def _rows(problem: Problem, out, index):
    """All candidate rows of one waypoint: 4 target rows (for target ``index``), ``2n``
    torque rows."""
    tip, rot, tau, _ = _unpack(problem, out)
    limit = problem.arm.torque_limit
    return jnp.concatenate(
        [_target_rows(problem, tip, rot, index), tau - limit, -tau - limit]
    )


@partial(jit, static_argnums=0)
def _evaluate(problem: Problem, z):
    """Objective, its gradient, constraint rows and their blocks, from one forward-mode
    pass.

    The expensive per-waypoint quantities (engine state, torques, obstacle cost) and
    their Jacobians in ``(θ_i, d)`` are computed once (``jacfwd``, vmapped over
    waypoints); the objective and the constraints are cheap functions of them, chained
    by hand.
    """
    theta, d = problem.split(z)
    out = jax.vmap(lambda th: _outputs(problem, th, d))(theta)
    jt, jd = jax.vmap(
        jax.jacfwd(lambda th, dd: _outputs(problem, th, dd), argnums=(0, 1)),
        in_axes=(0, None),
    )(theta, d)
    value, (g_out, g_theta, g_d) = jax.value_and_grad(
        lambda o, t, dd: _weighted(problem, o, t, dd), argnums=(0, 1, 2)
    )(out, theta, d)
    grad = jnp.concatenate(
        [
            (g_theta + jnp.einsum("wq,wqn->wn", g_out, jt)).ravel(),
            g_d + jnp.einsum("wq,wqm->m", g_out, jd),
        ]
    )
    index = jnp.asarray(_target_of_waypoint(problem))
    rows = jax.vmap(lambda o, k: _rows(problem, o, k))(out, index)
    drows = jax.vmap(jax.jacfwd(lambda o, k: _rows(problem, o, k)))(out, index)
    return (
        value,
        grad,
        rows,
        jnp.einsum("wrq,wqn->wrn", drows, jt),
        jnp.einsum("wrq,wqm->wrm", drows, jd),
    )


@partial(jit, static_argnums=0)
def objective_parts(problem: Problem, z) -> dict:
    """The unweighted objectives
    ``f_path, f_joints, f_length, f_torque, f_obstacle``."""
    theta, d = problem.split(z)
    out = jax.vmap(lambda th: _outputs(problem, th, d))(theta)
    return _parts(problem, out, theta, d)


def evaluate(problem: Problem, z: np.ndarray):
    """``(f, ∇f, g, ∂g/∂z)``: objective (eq. 1) and gradient, existing constraint rows
    (``g ≤ 0`` feasible) and their dense Jacobian ``(n_c, size)``."""
    value, grad, values, jac_theta, jac_d = (
        np.asarray(a) for a in _evaluate(problem, jnp.asarray(z))
    )
    mask = _row_mask(problem)
    n, n_w = problem.arm.num_joints, problem.num_waypoints
    wp, row = np.nonzero(mask)
    jac = np.zeros((wp.size, problem.size))
    cols = wp[:, None] * n + np.arange(n)[None, :]
    np.put_along_axis(jac, cols, jac_theta[wp, row], axis=1)
    jac[:, n_w * n :] = jac_d[wp, row]
    return float(value), grad, values[wp, row], jac


def constraints(problem: Problem, z: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``g(z)`` and its Jacobian (see :func:`evaluate`)."""
    return evaluate(problem, z)[2:]


@partial(jit, static_argnums=0)
def _waypoints(problem: Problem, z):
    """:func:`_waypoint` at every waypoint (compiled once per problem)."""
    theta, d = problem.split(z)
    loads = _loads(problem, d)
    return jax.vmap(lambda th: _waypoint(problem, th, d, loads))(theta)


def waypoint_report(problem: Problem, z) -> dict:
    """Per waypoint: tool positions, tip axes, torques (numpy), for output files and
    plots."""
    tip, rot, tau, obstacle = _waypoints(problem, jnp.asarray(z, dtype=float))
    return {
        "tip": np.asarray(tip),
        "axis": np.asarray(rot[:, :, 2]),
        "torque": np.asarray(tau),
        "obstacle": np.asarray(obstacle),
    }
