"""The design-and-trajectory NLP (paper 000, eq. 1-8) on a tiny 2-joint arm: waypoint
layout, exact gradients against finite differences, and a multi-start solve that reaches
targets generated from a known design (so a feasible point exists)."""

import numpy as np
import pytest
from arm_tasks import TINY_ARM, reached_targets

import linkopt  # noqa: F401  (float64)
from linkopt._arms.codesign import multistart, nlp
from linkopt._arms.codesign.task import loads_task

ARM = (
    TINY_ARM
    + """
[[obstacles]]
type = "sphere"
center = [-0.3, 0.0, 0.1]
radius = 0.1
[workspace]
lower = [-0.6, -0.6, -0.4]
upper = [0.6, 0.6, 0.6]
voxel = 0.04
[solver]
starts = 2
waypoints_per_target = 3
"""
)
DESIGN = np.array([0.1, 0.3])
POSES = np.array([[0.3, -0.5], [-0.4, 0.6], [0.9, 0.2]])


def _task():
    """The tiny arm with targets at the tool poses of ``POSES`` for the design
    ``DESIGN``."""
    text = ARM + reached_targets(ARM, DESIGN, POSES, axis=True)
    return loads_task(text, "tiny.toml")


@pytest.fixture(scope="module")
def problem():
    return nlp.prepare(_task())


def test_waypoint_layout_follows_distances():
    targets = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 3.0, 0], [1.0, 3.0, 1.0]])
    layout = nlp.waypoint_layout(targets, 4)
    assert (
        layout[0] == 0 and layout[-1] == 15
    )  # 16 waypoints, first and last are targets
    gaps = np.diff(layout) - 1
    assert gaps.sum() == 12 and np.all(gaps >= 1)
    assert gaps[1] > gaps[0] and gaps[1] > gaps[2]  # the long segment gets the most


def test_gradients_match_finite_differences(problem):
    z = multistart.initial_point(problem, 3)
    f, grad, g, jac = nlp.evaluate(problem, z)
    h = 1e-6
    rng = np.random.default_rng(0)
    for _ in range(3):
        v = rng.normal(size=z.size)
        fp, _, gp, _ = nlp.evaluate(problem, z + h * v)
        fm, _, gm, _ = nlp.evaluate(problem, z - h * v)
        np.testing.assert_allclose((fp - fm) / (2 * h), grad @ v, rtol=1e-5, atol=1e-5)
        np.testing.assert_allclose((gp - gm) / (2 * h), jac @ v, rtol=1e-5, atol=1e-6)


def test_multistart_reaches_every_target(problem):
    best, runs = multistart.solve(problem, starts=2, seed=0)
    assert len(runs) == 2 and best.feasible
    report = nlp.waypoint_report(
        problem, np.concatenate([best.theta.ravel(), best.design])
    )
    at = problem.target_waypoints
    tol = problem.task.tolerances
    error = np.sum((report["tip"][at] - problem.target_position) ** 2, axis=1)
    assert np.all(error <= tol["position"] + 1e-6)
    assert np.all(
        1 - np.sum(report["axis"][at] * problem.target_axis, axis=1)
        <= tol["tip"] + 1e-6
    )
    assert np.abs(report["torque"]).max() <= problem.arm.torque_limit + 1e-6
    assert np.all(best.design >= problem.arm.lower - 1e-9) and np.all(
        best.design <= problem.arm.upper + 1e-9
    )
