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


def _line_stays_assembled(motors, margin=2.0, samples=60, start=(0.0, 0.0)):
    """Whether the straight line from ``start`` (default rest) to each motor pair keeps
    the distal links ``margin`` short of stretched out (no forward singularity on the
    way)."""
    t = np.linspace(0.0, 1.0, samples)[:, None, None]
    start = np.asarray(start)
    e_l, e_r = elbows((start + t * (motors[None] - start)).reshape(-1, 2))
    gap = np.linalg.norm(e_r - e_l, axis=-1).reshape(samples, -1)
    return np.all(gap < 2 * L2 - margin, axis=0)


def test_large_single_solves_stay_on_the_rest_branch(five_bar):
    """Motors far from rest have two assemblies (tip on either side of the elbows).
    Solved without a start state, each lands on the rest branch (the closed form with
    the rest side), where one LM solve from the rest state can land on either."""
    motors = np.random.default_rng(11).uniform(-1.4, 1.4, size=(400, 2))
    motors = motors[_line_stays_assembled(motors)]
    assert len(motors) > 100
    solution = linkopt.solve_fk(five_bar, motors)
    assert np.all(np.asarray(solution.converged))
    tips = np.asarray(linkopt.point_positions(five_bar, solution.state))[:, 0, :2]
    np.testing.assert_allclose(tips, forward(motors), atol=1e-8)
    plain = linkopt.solve_fk(five_bar, motors, start=linkopt.rest_state(five_bar))
    plain_tips = np.asarray(linkopt.point_positions(five_bar, plain.state))[:, 0, :2]
    jumped = np.asarray(plain.converged) & np.any(
        np.abs(plain_tips - forward(motors)) > 1e-3, axis=1
    )
    assert jumped.sum() > 0  # the plain solve does jump: the test above has teeth


def test_a_single_solve_past_the_reach_says_how_far_it_got(five_bar):
    """Pulling both cranks apart stretches the distal links out (a forward
    singularity) before the requested motors: not converged, never another branch."""
    motors = np.array([0.9, -0.9])
    assert not _line_stays_assembled(motors[None], margin=0.0)[0]
    solution = linkopt.solve_fk(five_bar, motors)
    assert not bool(solution.converged)
    progress = float(solution.progress)
    assert 0.0 < progress < 1.0
    reached = np.asarray(linkopt.motor_values(five_bar, solution.state))
    np.testing.assert_allclose(reached, progress * motors, atol=1e-8)
    assert _line_stays_assembled(reached[None], margin=0.0)[0]


def test_path_rows_past_a_jump_are_subdivided_not_skipped(five_bar):
    """Two rows far apart: the path continues between them in small steps and ends on
    the rest branch, as the single solve does."""
    motors = np.array([[0.0, 0.0], [1.3, 0.4], [-1.2, -1.0]])
    assert _line_stays_assembled(motors[1:2])[0]
    assert _line_stays_assembled(motors[2:], start=motors[1])[0]
    path = linkopt.solve_fk_path(five_bar, motors)
    assert np.all(np.asarray(path.converged))
    tips = np.asarray(linkopt.point_positions(five_bar, path.state))[:, 0, :2]
    np.testing.assert_allclose(tips, forward(motors), atol=1e-8)
