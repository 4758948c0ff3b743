"""The dense cycle sweep (linkopt._synth.cycle): the traced curve against the
closed-form coupler curve, and each defect on a four-bar built to have it."""

import numpy as np
import pytest
from synth_fourbars import coupler_curve, four_bar

import linkopt
from linkopt._synth.cycle import in_order, jump_steps, rotation_angle, sweep_cycle
from linkopt._synth.targets import Targets

# Crank-rocker (Grashof: 20 + 70 <= 50 + 60), coupler point (15, 10) in B->C's frame.
GRASHOF = (20.0, 70.0, 50.0, 60.0, 15.0, 10.0)
# Non-Grashof (40 + 60 > 50 + 45): the crank stops where |BD| = b - c.
TRIPLE_ROCKER = (40.0, 60.0, 50.0, 45.0, 10.0, 5.0)
START = np.pi / 2  # the files' crank angle at rest


def _curve(lengths, motors, branch=1):
    return np.c_[coupler_curve(*lengths, START + motors, branch), np.zeros(len(motors))]


def _path(values, closed=True, tolerance=1e-3, motors=None):
    return Targets("path", "tip", values, motors, closed, tolerance)


@pytest.fixture(scope="module")
def crank_rocker():
    return four_bar(*GRASHOF)


@pytest.fixture(scope="module")
def fine_turn(crank_rocker):
    return sweep_cycle(crank_rocker, None, _path(_curve(GRASHOF, np.arange(8) * 0.7)))


def test_full_turn_traces_the_closed_form_coupler_curve(fine_turn):
    exact = _curve(GRASHOF, fine_turn.motors[:, 0])
    assert fine_turn.solved.all() and fine_turn.traced.shape == (360, 3)
    np.testing.assert_allclose(fine_turn.traced, exact, atol=1e-9)
    np.testing.assert_allclose(fine_turn.motors[:, 0], np.arange(360) * np.pi / 180)


def test_full_turn_of_a_crank_rocker_has_no_defect(fine_turn):
    assert fine_turn.defect is None and fine_turn.in_order
    assert fine_turn.least_sigma > 1.0 / fine_turn.alpha_minus
    assert fine_turn.largest_residual < 1e-10
    assert fine_turn.least_clearance is None
    # the targets lie on the curve between grid steps: the segment distance is
    # second order in the step (0.0175 rad x 20 mm crank: chord sag < 1e-3 mm)
    assert fine_turn.distances.max() < 1e-3
    steps = np.round(np.arange(8) * 0.7 * 180 / np.pi).astype(int)
    assert np.all(np.abs(fine_turn.passed_at - steps) <= 1)


def test_non_grashof_crank_loses_its_assembly_at_the_limit_angle():
    mech = four_bar(*TRIPLE_ROCKER)
    a, b, c, d = TRIPLE_ROCKER[:4]
    # |BD|^2 = a^2 + d^2 - 2 a d cos(theta) = (b - c)^2 at the crank's limit
    limit = 2 * np.pi - np.arccos((a * a + d * d - (b - c) ** 2) / (2 * a * d)) - START
    targets = _path(_curve(TRIPLE_ROCKER, np.arange(5.0)), tolerance=0.01)
    report = sweep_cycle(mech, None, targets)
    lost = int(np.flatnonzero(~report.solved)[0])
    assert report.motors[lost - 1, 0] < limit < report.motors[lost, 0]
    assert report.defect.startswith(f"lost assembly (branch defect) at step {lost},")
    assert f"motor {report.motors[lost, 0]:.6g}" in report.defect
    assert np.isnan(report.traced[lost:]).all()
    # the dead centre at the limit: forward sigma_min falls on the approach
    assert report.least_sigma < 1.0 / report.alpha_minus


def test_targets_on_the_other_assembly_branch_are_not_reached(crank_rocker):
    other = _curve(GRASHOF, np.arange(6.0), branch=-1)
    report = sweep_cycle(crank_rocker, None, _path(other))
    assert report.solved.all()
    assert report.defect.startswith("target ") and "not reached" in report.defect
    assert np.all(report.distances > 1.0)  # the two circuits are millimetres apart


def test_targets_in_reverse_order_are_an_order_defect(crank_rocker):
    ahead = _curve(GRASHOF, np.arange(8) * 0.7)
    report = sweep_cycle(crank_rocker, None, _path(ahead[::-1]))
    assert not report.in_order
    assert report.defect.startswith("targets out of order")
    assert report.distances.max() < 1e-3  # every target is on the curve
    backwards = sweep_cycle(crank_rocker, None, _path(ahead[::-1]), direction=-1)
    assert backwards.in_order and backwards.defect is None
    np.testing.assert_allclose(backwards.motors[1, 0], -np.pi / 180)


def test_in_order_is_cyclic_only_for_closed_curves():
    assert in_order(np.array([3, 5, 9]), closed=False)
    assert not in_order(np.array([5, 9, 3]), closed=False)
    assert in_order(np.array([5, 9, 3]), closed=True)  # one wrap
    assert not in_order(np.array([9, 5, 3]), closed=True)


def test_timed_targets_are_judged_at_their_motor_values(crank_rocker):
    motors = np.array([0.3, 1.1, 2.0, 4.5])
    values = _curve(GRASHOF, motors)
    report = sweep_cycle(crank_rocker, None, _path(values, motors=motors[:, None]))
    np.testing.assert_allclose(report.motors[report.passed_at, 0], motors)
    assert report.distances.max() < 1e-9 and report.defect is None
    late = _path(values, motors=motors[:, None] + 0.05, tolerance=1e-2)
    assert "not reached" in sweep_cycle(crank_rocker, None, late).defect


def test_open_sweep_over_a_span_and_function_targets(crank_rocker):
    """The rocker angle (the output, from its rest value) against Freudenstein's
    geometry: the rocker pin by circle intersection."""
    motors = np.array([0.2, 0.6, 1.0])
    pin = coupler_curve(*GRASHOF[:4], 0.0, 0.0, START + motors, 1)  # B itself
    rocker = coupler_curve(*GRASHOF[:4], GRASHOF[1], 0.0, START + motors, 1)  # C
    rest = coupler_curve(*GRASHOF[:4], GRASHOF[1], 0.0, [START], 1)[0]
    angle = np.arctan2(rocker[:, 1], rocker[:, 0] - 60.0)
    angle -= np.arctan2(rest[1], rest[0] - 60.0)
    assert np.all(np.linalg.norm(rocker - pin, axis=1) - 70.0 < 1e-9)
    targets = Targets("function", "rocker", angle, None, False, 1e-4)
    # 360 steps: the 512-row path program of the full turn above (fine_turn)
    report = sweep_cycle(crank_rocker, None, targets, steps=360, span=(0.0, 1.2))
    assert report.traced.shape == (360,) and report.defect is None
    np.testing.assert_allclose(report.motors[[0, -1], 0], [0.0, 1.2])
    assert report.distances.max() < 1e-4


def test_motion_targets_are_the_coupler_poses(crank_rocker):
    """The coupler's frame origin is the midpoint of B and C (its anchors at rest);
    it turns about z by the change of the direction B->C."""
    motors = np.array([0.5, 2.5, 4.0])
    b = coupler_curve(*GRASHOF[:4], 0.0, 0.0, START + motors, 1)
    c = coupler_curve(*GRASHOF[:4], GRASHOF[1], 0.0, START + motors, 1)
    rest = coupler_curve(*GRASHOF[:4], 0.0, 0.0, [START], 1)[0]
    rest_c = coupler_curve(*GRASHOF[:4], GRASHOF[1], 0.0, [START], 1)[0]
    turn = np.arctan2(*(c - b).T[::-1]) - np.arctan2(*(rest_c - rest)[::-1])
    poses = np.c_[(b + c) / 2, np.zeros(3), np.cos(turn / 2), np.zeros((3, 2))]
    poses = np.c_[poses, np.sin(turn / 2)]
    targets = Targets("motion", "coupler", poses, motors[:, None], True, 1e-9)
    report = sweep_cycle(crank_rocker, None, targets)
    assert report.traced.shape == (360 + 3, 7)
    assert report.defect is None and report.distances.max() < 1e-9


def test_collision_clearance_is_reported_and_judged():
    """The file's coupler sweeps through the ground link for part of the turn."""
    mech = linkopt.load("mechanisms/four_bar_collision.toml")
    body = mech.body_names.index("coupler")
    rest = np.asarray(linkopt.rest_state(mech))[7 * body : 7 * body + 7]
    pose = np.r_[rest[:3] * mech.length_scale, rest[3:]]
    targets = Targets("motion", "coupler", pose[None], None, True, 1e-6)
    report = sweep_cycle(mech, None, targets, steps=90)
    states = np.asarray(linkopt.solve_fk_path(mech, report.motors).state)
    gaps = linkopt.clearance(mech, states).minimum
    assert report.least_clearance == pytest.approx(gaps.min(), abs=1e-12)
    first = int(np.flatnonzero(gaps < mech.collision.clearance)[0])
    assert report.defect.startswith(f"collision at step {first},")


def test_unknown_target_name_is_refused(crank_rocker):
    with pytest.raises(linkopt.InputError, match="targets.name: 'nowhere'"):
        sweep_cycle(
            crank_rocker,
            None,
            Targets("path", "nowhere", np.zeros((2, 3)), None, True, 1.0),
        )


def test_rotation_angle_agrees_with_acos_and_stays_accurate_near_zero():
    rng = np.random.default_rng(7)
    q, t = rng.normal(size=(2, 50, 4))
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    acos = 2 * np.arccos(np.clip(np.abs(np.sum(q * t, axis=1)), 0, 1))
    np.testing.assert_allclose(rotation_angle(q, t), acos, atol=1e-7)
    tiny = np.array([np.cos(5e-10), 0.0, 0.0, np.sin(5e-10)])  # a 1e-9 rad turn
    assert rotation_angle(tiny, -np.eye(4)[0]) == pytest.approx(1e-9, rel=1e-6)


def test_two_motor_sweeps_with_timing_and_by_reaching_each_target():
    """Five-bar: timed rows are swept exactly (closed back to the first); without
    timing, Gauss-Newton on the motors finds the rows that generated the points."""
    mech = linkopt.load("mechanisms/five_bar.toml")
    motors = np.array([[0.0, 0.0], [0.2, 0.1], [0.3, -0.1], [0.1, -0.2]])
    states = linkopt.solve_fk(mech, motors).state
    points = np.asarray(linkopt.point_positions(mech, states))[:, 0]
    timed = Targets("path", "ee", points, motors, True, 1e-9)
    report = sweep_cycle(mech, None, timed, steps=60)
    np.testing.assert_allclose(report.motors[report.passed_at], motors)
    assert report.defect is None and report.distances.max() < 1e-9
    free = Targets("path", "ee", points, None, False, 1e-9)
    report = sweep_cycle(mech, None, free, steps=60)
    np.testing.assert_allclose(report.motors[report.passed_at], motors, atol=1e-8)
    assert report.defect is None and report.in_order


def test_open_sweep_spans_the_motor_limits():
    limited = four_bar(*GRASHOF, motor="min = -0.5\nmax = 1.0\n")
    targets = _path(_curve(GRASHOF, np.array([-0.4, 0.9])), False, tolerance=0.01)
    # 360 steps: the crank-rocker's full-turn path program (limits are numbers)
    report = sweep_cycle(limited, None, targets, steps=360, span=(0.0, 3.0))
    np.testing.assert_allclose(report.motors[[0, -1], 0], [-0.5, 1.0])
    assert report.defect is None and report.in_order
    late = _path(targets.values, closed=False, motors=np.array([[0.0], [2.0]]))
    with pytest.raises(linkopt.InputError, match="^targets.motors: timing values"):
        sweep_cycle(limited, None, late)


def test_sweeps_that_cannot_be_made_are_refused_naming_the_argument(crank_rocker):
    point = np.zeros((2, 3))
    with pytest.raises(linkopt.InputError, match="^span: an open sweep"):
        sweep_cycle(crank_rocker, None, _path(point, closed=False))
    with pytest.raises(linkopt.InputError, match="^direction: expected 1 or -1"):
        sweep_cycle(crank_rocker, None, _path(point), direction=2)
    with pytest.raises(linkopt.InputError, match="^steps: expected"):
        sweep_cycle(crank_rocker, None, _path(point), steps=1)
    slider = linkopt.load("mechanisms/slider_crank_linear.toml")
    with pytest.raises(linkopt.InputError, match="^targets.closed: .* is linear"):
        sweep_cycle(slider, None, Targets("path", "crank_pin", point, None, True, 1.0))
    five_bar = linkopt.load("mechanisms/five_bar.toml")
    function = Targets("function", "x", np.zeros(2), None, False, 1.0)
    with pytest.raises(linkopt.InputError, match="^targets.kind: a function target"):
        sweep_cycle(five_bar, None, function)


def test_jump_steps_flag_a_spike_in_the_rate_not_a_longer_step():
    """State change per motor change: one step ten-odd times the median rate is a
    jump; a step twice as long moving the state twice as far is not; a state
    change with no motor change is; unsolved neighbours are not judged."""
    solved = np.ones(7, dtype=bool)
    moved = np.array([0.1, 0.1, 0.2, 0.1, 0.1, 0.1])
    jumps = np.array([0.05, 0.05, 0.1, 0.05, 0.8, 0.05])
    assert list(np.flatnonzero(jump_steps(solved, jumps, moved))) == [5]
    still = jump_steps(solved, jumps * [1, 1, 1, 1, 0.1, 1], moved * [1, 0, 1, 1, 1, 1])
    assert list(np.flatnonzero(still)) == [2]
    solved[4] = False
    assert not jump_steps(solved, jumps, moved).any()


def test_timed_targets_on_a_turn_the_other_way(crank_rocker):
    """direction -1: the timing values are taken modulo a turn, below the rest."""
    motors = np.array([0.3, 4.5, 2.0])
    values = _curve(GRASHOF, motors)
    timed = _path(values, motors=motors[:, None], tolerance=1e-9)
    report = sweep_cycle(crank_rocker, None, timed, direction=-1)
    np.testing.assert_allclose(report.motors[report.passed_at, 0], motors - 2 * np.pi)
    assert np.all(np.diff(report.motors[:, 0]) < 0)
    assert report.distances.max() < 1e-9 and report.in_order and report.defect is None
