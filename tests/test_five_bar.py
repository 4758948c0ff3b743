"""Five-bar forward and backward kinematics against the closed form (circle
intersection)."""

import numpy as np
import pytest
from five_bar_closed_form import B_L, B_R, L1, L2, cross, elbows, forward, inverse

import linkopt


def sample_motors(n, seed=7):
    """Motors within 0.35 rad of rest, kept well away from the forward singularity.

    Every test draws from its own seeded generator: under pytest-xdist the order of the
    tests in a process varies, so a module-wide generator would hand out other
    numbers."""
    motors = np.random.default_rng(seed).uniform(-0.35, 0.35, size=(n, 2))
    e_l, e_r = elbows(motors)
    gap = np.linalg.norm(e_r - e_l, axis=-1)
    return motors[gap < 2 * L2 - 10.0]


def test_rest_pose_is_assembled(five_bar):
    solution = linkopt.solve_fk(five_bar, np.zeros(2))
    assert bool(solution.converged) and int(solution.iterations) == 0
    np.testing.assert_allclose(
        linkopt.point_positions(five_bar, solution.state)[0],
        [0.0, 70.0, 0.0],
        atol=1e-12,
    )


def test_forward_kinematics_matches_circle_intersection(five_bar):
    motors = sample_motors(300)
    assert len(motors) > 200
    solution = linkopt.solve_fk(five_bar, motors)
    assert np.all(solution.converged)
    assert float(np.max(solution.residual)) <= 1e-10
    tips = np.asarray(linkopt.point_positions(five_bar, solution.state))[:, 0]
    np.testing.assert_allclose(tips[:, :2], forward(motors), atol=1e-9)
    np.testing.assert_allclose(tips[:, 2], 0.0, atol=1e-9)
    np.testing.assert_allclose(
        linkopt.motor_values(five_bar, solution.state), motors, atol=1e-10
    )


def test_backward_kinematics_matches_closed_form_inverse(five_bar):
    rng = np.random.default_rng(8)
    tips = np.stack([rng.uniform(-25, 25, 300), rng.uniform(45, 80, 300)], -1)
    # keep 2 mm inside the reach L1 + L2 of both cranks (the box's top corners leave it)
    inside = (np.linalg.norm(tips - B_L, axis=1) < L1 + L2 - 2.0) & (
        np.linalg.norm(tips - B_R, axis=1) < L1 + L2 - 2.0
    )
    tips = tips[inside]
    assert len(tips) > 250
    solution = linkopt.solve_bk(five_bar, tips)
    assert np.all(solution.converged)
    np.testing.assert_allclose(
        linkopt.output_values(five_bar, solution.state), tips, atol=1e-9
    )
    np.testing.assert_allclose(
        linkopt.motor_values(five_bar, solution.state), inverse(tips), atol=1e-9
    )


def test_fk_bk_fk_round_trip(five_bar):
    motors = sample_motors(100)
    first = linkopt.solve_fk(five_bar, motors)
    outputs = linkopt.output_values(five_bar, first.state)
    back = linkopt.solve_bk(five_bar, outputs)
    assert np.all(back.converged)
    recovered = np.asarray(linkopt.motor_values(five_bar, back.state))
    np.testing.assert_allclose(recovered, motors, atol=1e-9)
    again = linkopt.solve_fk(five_bar, recovered, start=back.state)
    np.testing.assert_allclose(again.state, first.state, atol=1e-9)


def test_path_follows_the_rest_branch(five_bar):
    """Continuation keeps the tip on the rest branch (left of the elbow-to-elbow
    vector)."""
    t = np.linspace(0.0, 1.0, 41)[:, None]
    motors = t * np.array([0.5, -0.2])
    path = linkopt.solve_fk_path(five_bar, motors)
    assert np.all(path.converged)
    tips = np.asarray(linkopt.point_positions(five_bar, path.state))[:, 0, :2]
    e_l, e_r = elbows(motors)
    assert np.all(cross(e_r - e_l, tips - e_l) > 0)
    np.testing.assert_allclose(tips, forward(motors), atol=1e-9)


def test_unreachable_target_is_reported_not_nan(five_bar):
    solution = linkopt.solve_bk(five_bar, np.array([0.0, 200.0]))
    assert not bool(solution.converged)
    assert np.isfinite(float(solution.residual)) and float(solution.residual) > 1e-3
    assert np.all(np.isfinite(np.asarray(solution.state)))


@pytest.mark.parametrize("design", [[15.0, 37.0, 36.0], [20.0, 45.0, 30.0]])
def test_design_vector_moves_mirrored_joints(five_bar, design):
    state = linkopt.rest_state(five_bar)
    joints = np.asarray(linkopt.joint_positions(five_bar, state, design=design))
    names = five_bar.joint_names
    right = joints[names.index("base_right")]
    left = joints[names.index("base_left")]
    np.testing.assert_allclose(left, right * [-1, 1, 1], atol=1e-12)
    np.testing.assert_allclose(right[0], design[0])
    elbow_r, elbow_l = (
        joints[names.index("elbow_right")],
        joints[names.index("elbow_left")],
    )
    np.testing.assert_allclose(elbow_r[:2], design[1:])
    np.testing.assert_allclose(elbow_l[:2], [-design[1], design[2]])
    assert bool(linkopt.solve_fk(five_bar, np.zeros(2), design=design).converged)
