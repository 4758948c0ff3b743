"""Joint elimination (paper 000, Algorithm 1) on a small case: a 3-joint arm whose
middle link is short is merged into a 2-joint arm. With two position targets the merged
arm's stacked Jacobian (6 rows; 2 x 2 joint angles and 2 design columns) is square, so
the algorithm can keep both tools on their targets while the segment shrinks, and its δ
is far below that of merging without compensation."""

from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import linkopt  # noqa: F401  (float64)
from linkopt._arms.codesign import elimination as elim
from linkopt._arms.codesign import nlp
from linkopt._arms.codesign.model import chain
from linkopt._arms.codesign.task import loads_task

ARM = """
[task]
name = "small"
gravity = [0.0, 0.0, -9.81]
torque_limit = 9.0
module_radius = 0.03
[[modules]]
type = "base"
z = 0.3
[[modules]]
type = "joint"
mass = 0.3
[[modules]]
type = "link"
length = { min = 0.1, max = 0.6, init = 0.3 }
twist = { min = -3.2, max = 3.2, init = 1.5707963267948966 }
mass = 0.2
[[modules]]
type = "joint"
mass = 0.3
[[modules]]
type = "link"
length = { min = 0.02, max = 0.6, init = 0.08 }
twist = { min = -3.2, max = 3.2, init = 0.15 }
mass = 0.1
[[modules]]
type = "joint"
mass = 0.3
[[modules]]
type = "tool"
length = 0.15
mass = 0.1
"""
POSES = np.array([[0.2, -0.6, 0.5], [0.7, -0.3, 0.9]])


@pytest.fixture(scope="module")
def case():
    skeleton = loads_task(
        ARM + "[[targets]]\nposition = [0.0, 0.0, 0.0]\n", "small.toml"
    )
    d0 = skeleton.arm.d0
    text = ARM
    for theta in POSES:
        ends, _ = chain(skeleton.arm.modules, jnp.asarray(theta), jnp.asarray(d0))
        text += f"[[targets]]\nposition = {list(map(float, ends[-1][1]))}\n"
    problem = nlp.prepare(loads_task(text, "small.toml"))
    return problem, d0


def test_elimination_reaches_small_delta(case):
    problem, d0 = case
    assert (
        elim.delta_error(problem, problem.arm, POSES, d0) < 1e-20
    )  # the start is exact
    settings = elim.EliminationSettings(
        alpha=0.02, iterations=250
    )  # half the paper's 500 steps
    result = elim.eliminate(problem, POSES, d0, 1, settings)
    _, _, d_j = elim.segment_arm(problem.arm, 1, d0)
    assert result.iterations == settings.iterations
    np.testing.assert_allclose(
        result.segment,
        np.linalg.norm(d_j) * (1 - settings.alpha) ** settings.iterations,
        rtol=1e-9,
    )
    assert result.arm.num_joints == 2 and result.theta.shape == (2, 2)
    assert result.delta < 1e-4
    # Merging the same joints without Algorithm 1 (drop the link, add the angles):
    naive = elim.merge_trajectory(POSES, 1)
    assert elim.delta_error(problem, result.arm, naive, d0[:2]) > 100 * result.delta


def _reference_poses(arm, theta, d):
    """Tool pose and its ``(θ, d)`` Jacobians of ``arm`` itself (its own engine model),
    the arm-per-program route the padded program replaced."""
    from linkopt._arms.codesign.model import tool_pose

    def pose(th, dd):
        tip, rot, _, _ = tool_pose(arm, th, dd)
        return tip, rot

    (tip, rot), (dp, dr) = pose(theta, d), jax.jacfwd(pose, argnums=(0, 1))(theta, d)
    return [np.asarray(a) for a in (tip, rot, dp[0], dp[1], dr[0], dr[1])]


def test_padded_poses_match_the_reduced_arms(case):
    """The root-arm program with a layout gives the segment arm's and the merged arm's
    own tool poses and Jacobians (rounding only: the engine models differ in length
    scale and bodies)."""
    problem, d0 = case
    theta = POSES[0]
    seg, keep, d_j = elim.segment_arm(problem.arm, 1, d0)
    d_seg = np.concatenate([d0[keep], 0.3 * d_j])  # a segment away from d_j
    merged = elim.merged_arm(problem.arm, 1, keep)
    for arm, padded, d in (
        (seg, elim.pad(problem.arm, d0, 1), d_seg),
        (merged, elim.pad(merged, d0[keep]), d0[keep]),
    ):
        tip, rot, dp_t, dp_d, dr_t, dr_d = _reference_poses(
            arm, jnp.asarray(theta[: arm.num_joints]), jnp.asarray(d)
        )
        got_tip, got_rot, j_theta, j_d = elim.poses(
            padded, theta[None, : arm.num_joints], d
        )
        np.testing.assert_allclose(got_tip[0], tip, atol=1e-12)
        np.testing.assert_allclose(got_rot[0], rot, atol=1e-12)
        np.testing.assert_allclose(j_theta[0, :3], dp_t, atol=1e-10)
        np.testing.assert_allclose(j_d[0, :3], dp_d, atol=1e-10)
        w = np.einsum("abk,cb->ack", dr_d, rot)  # the twist's angular rows in d
        np.testing.assert_allclose(
            j_d[0, 3:], np.stack([w[2, 1], w[0, 2], w[1, 0]]), atol=1e-10
        )
        w = np.einsum("abk,cb->ack", dr_t, rot)
        np.testing.assert_allclose(
            j_theta[0, 3:], np.stack([w[2, 1], w[0, 2], w[1, 0]]), atol=1e-10
        )


def test_elimination_steps_share_one_program(case):
    """Every candidate of every elimination step runs the same compiled pose program:
    the arm's structure is data (a layout over the root arm), so a second candidate,
    the merged arm's δ and a second elimination step compile nothing new."""
    problem, d0 = case
    settings = elim.EliminationSettings(iterations=3)
    first = elim.eliminate(problem, POSES, d0, 0, settings)
    programs = elim.root_poses._tuned._cache_size()
    second = elim.eliminate(problem, POSES, d0, 1, settings)
    reduced = replace(problem, arm=second.arm)
    third = elim.eliminate(reduced, second.theta, second.design, 0, settings)
    assert third.arm.num_joints == 1 and third.theta.shape == (2, 1)
    assert first.arm is not second.arm  # distinct structures, one program
    assert elim.root_poses._tuned._cache_size() == programs
