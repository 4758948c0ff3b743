"""Closed-form starts of a planar four-bar path synthesis (linkopt._synth.starts) and
the synthesis objective's order penalty: the closed-form coupler curve keeps every
link's length and the coupler rigid, the refined starts meet the precision points
with the asked transmission angle, and the order penalty is zero exactly for
targets met in order (either sense, cyclically for a full turn)."""

from __future__ import annotations

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

import linkopt
from linkopt._synth import objective, starts
from linkopt._synth.targets import Targets

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "benchmarks" / "synthesis" / "readme_4.toml"
POINTS = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, 0.0], [2.0, 1.0, 0.0], [3.0, 0.0, 0.0]])


@pytest.fixture(scope="module")
def mech():
    return linkopt.load(README)


def _targets(least=30.0, kind="path", motors=None):
    return Targets(kind, "tip", POINTS, motors, False, 0.03, "test", least)


def test_the_closed_form_coupler_curve_keeps_the_links_and_the_coupler_rigid(mech):
    frame = starts.frame_of(mech, _targets())
    rest = starts.placed(mech, frame, frame.p0)
    a, b0, c0, d, p0 = rest
    phi = np.linspace(-np.pi, np.pi, 37)
    curve = starts.coupler_points(rest, phi)
    np.testing.assert_allclose(starts.coupler_points(rest, np.zeros(1))[0], p0)
    # rebuild B and C as the closed form does and check every length
    b = a + np.stack([np.cos(phi), np.sin(phi)], 1) @ np.array(
        [[b0[0] - a[0], b0[1] - a[1]], [-(b0[1] - a[1]), b0[0] - a[0]]]
    )
    np.testing.assert_allclose(np.linalg.norm(b - a, axis=1), np.linalg.norm(b0 - a))
    # the coupler point keeps its distance from B (rigid coupler)
    np.testing.assert_allclose(
        np.linalg.norm(curve - b, axis=1), np.linalg.norm(p0 - b0), rtol=1e-12
    )
    # the file's four-bar is a double-crank: every crank angle is reached, and the
    # point's distance from the pivot D stays within the coupler's reach of it
    far = np.linalg.norm(c0 - d) + np.linalg.norm(p0 - c0)
    assert np.all(np.linalg.norm(curve - d, axis=1) <= far + 1e-9)


def test_the_refined_starts_meet_the_points_with_the_asked_transmission(mech):
    targets = _targets(least=30.0)
    designs = starts.candidates(
        mech, targets, seed=0, count=32, min_transmission_deg=30.0
    )
    assert designs.shape == (32, mech.design.size)
    assert np.all(designs >= mech.design.lower) and np.all(designs <= mech.design.upper)
    problem = starts.problem_of(mech, targets, 30.0)
    frame, goals = problem.frame, problem.goals
    # the plane is the four-bar's, through its pivot A: the targets shifted
    np.testing.assert_allclose(goals, POINTS[:, :2] - frame.plane[0, :2])
    rest = starts.placed(mech, frame, designs[0])
    assert np.degrees(starts.worst_transmission(rest)) >= 30.0
    # every target lies on the closed-form coupler curve of the best start
    curve = starts.coupler_points(rest, np.linspace(-np.pi, np.pi, 20001))
    gaps = np.min(np.linalg.norm(curve[:, None] - goals[None], axis=-1), axis=0)
    assert np.max(gaps) < 1e-3


def test_the_starts_apply_to_untimed_coupler_paths_of_a_four_bar_only(mech):
    assert starts.applies(mech, _targets())
    assert not starts.applies(mech, _targets(motors=np.zeros((4, 1))))
    five = linkopt.load(ROOT / "mechanisms" / "five_bar.toml")
    assert not starts.applies(five, Targets("path", "ee", POINTS, None, False, 1.0))


@pytest.mark.parametrize(
    ("places", "cyclic", "in_order"),
    [
        ([0.0, 10.0, 20.0, 30.0], False, True),
        ([30.0, 20.0, 10.0, 0.0], False, True),  # the motor run the other way
        ([0.0, 20.0, 10.0, 30.0], False, False),
        ([50.0, 70.0, 5.0, 20.0], True, True),  # one wrap of the full turn
        ([50.0, 20.0, 5.0, 70.0], True, True),  # the other sense, cyclically
        ([50.0, 5.0, 70.0, 20.0], True, False),
    ],
)
def test_the_order_penalty_is_zero_exactly_for_targets_in_order(
    places, cyclic, in_order
):
    value = float(objective.descents(jnp.asarray(places), cyclic, 72))
    assert (value == 0.0) == in_order
    if not in_order:
        assert value > 1e-3
