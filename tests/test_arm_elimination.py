"""Joint elimination (paper 000, Algorithm 1) on a small case: a 3-joint arm whose
middle link is short is merged into a 2-joint arm. With two position targets the merged
arm's stacked Jacobian (6 rows; 2 x 2 joint angles and 2 design columns) is square, so
the algorithm can keep both tools on their targets while the segment shrinks, and its δ
is far below that of merging without compensation."""

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
