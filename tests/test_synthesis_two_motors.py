"""A path without timing for a two-motor mechanism (the five-bar): each target is
reached by the motors that the inverse kinematics finds, in turn from the rest pose,
and the straight motor-space motion between consecutive targets is swept for
defects."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._files.synthesis import build
from linkopt._synth.sweep import reaching_timing
from linkopt.synthesis import score, verify

STEPS = 48


@pytest.fixture(scope="module")
def mech():
    return linkopt.load(MECHANISMS / "five_bar.toml")


def _reached(mech, motors):
    """The end effector where the file's design puts it at each row of ``motors``,
    each solved from the last."""
    state, points = linkopt.rest_state(mech), []
    for row in motors:
        state = linkopt.solve_fk(mech, row, start=state).state
        points.append(np.asarray(linkopt.point_positions(mech, state))[0])
    return np.array(points)


def _targets(mech, values, tolerance=1e-3):
    return build(mech.source, "test", "path", "ee", values, None, False, tolerance)


def test_the_timing_is_the_motors_that_put_the_point_on_each_target(mech):
    rest = np.asarray(linkopt.motor_values(mech, linkopt.rest_state(mech)))
    motors = rest + np.array([[0.05, -0.03], [0.12, 0.02], [0.16, 0.10]])
    targets = _targets(mech, _reached(mech, motors))
    timing = reaching_timing(mech, mech.design.p0, targets)
    np.testing.assert_allclose(timing, motors, atol=1e-7)


def test_an_untimed_two_motor_path_is_scored_and_verified_segment_by_segment(mech):
    rest = np.asarray(linkopt.motor_values(mech, linkopt.rest_state(mech)))
    motors = rest + np.array([[0.05, -0.03], [0.12, 0.02], [0.16, 0.10]])
    values = _reached(mech, motors)
    result = score(mech, _targets(mech, values), steps=STEPS)
    assert result.targets.motors is None  # the result keeps the targets untimed
    assert result.max_distance < 1e-6 and result.feasible
    report = verify(mech, result)
    assert report.defect is None and report.in_order
    assert np.max(report.distances) < 1e-6
    # the sweep runs from the first target's motors through the others in turn
    np.testing.assert_allclose(report.motors[0], motors[0], atol=1e-7)
    at = np.asarray(report.passed_at)
    np.testing.assert_allclose(report.motors[at], motors, atol=1e-7)
    # a target that the linkage cannot reach is not met and is named as missed
    far = values + np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0], [150.0, 0.0, 0.0]])
    missed = verify(mech, score(mech, _targets(mech, far), steps=STEPS))
    assert missed.defect is not None and np.max(missed.distances) > 1.0
