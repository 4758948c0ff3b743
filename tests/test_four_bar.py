"""The crank-rocker four-bar (``mechanisms/four_bar.toml``) against its closed form.

Circle intersection gives the rocker pin ``C`` for a crank angle; the rocker angle
and the coupler point (a reported output) follow. The backward singularities of the
crank/rocker pair are the toggle positions, where crank and coupler are collinear:
the textbook Jacobian of the loop-closure in (crank, coupler) angles has determinant
``a b sin(θ2 - θ3)``, and σ_min of ``∂C_BK/∂s`` follows ``|sin(θ2 - θ3)|``.
"""

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt

A, B, C, D = 20.0, 70.0, 50.0, 60.0  # crank, coupler, rocker, ground (mm)
POINT = np.array([35.0, 55.0])  # coupler point at rest


def _circles(p, rp, q, rq):
    """The intersection of the circles ``|x - p| = rp`` and ``|x - q| = rq`` left of
    ``p → q`` (the upper branch of the rest pose)."""
    p, q = np.asarray(p, float), np.asarray(q, float)
    v = q - p
    dist = np.linalg.norm(v)
    along = (rp * rp - rq * rq + dist * dist) / (2 * dist)
    height = np.sqrt(rp * rp - along * along)
    return p + along * v / dist + height * np.array([-v[1], v[0]]) / dist


def _pose(crank):
    """Crank pin, rocker pin, rocker angle and coupler angle (both from rest) and the
    coupler point, for the crank turned by ``crank`` from rest."""
    b0, c0 = np.array([0.0, A]), _circles([0.0, A], B, [D, 0.0], C)
    theta = np.pi / 2 + crank
    b = A * np.array([np.cos(theta), np.sin(theta)])
    c = _circles(b, B, [D, 0.0], C)
    rocker = np.arctan2(c[1], c[0] - D) - np.arctan2(c0[1], c0[0] - D)
    turn = np.arctan2(*(c - b)[::-1]) - np.arctan2(*(c0 - b0)[::-1])
    rot = np.array([[np.cos(turn), -np.sin(turn)], [np.sin(turn), np.cos(turn)]])
    return b, c, rocker, turn, b + rot @ (POINT - b0)


def _wrapped(angle):
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


@pytest.fixture(scope="module")
def four_bar():
    return linkopt.load(MECHANISMS / "four_bar.toml")


@pytest.fixture(scope="module")
def revolution(four_bar):
    """FK by continuation once around the crank's full turn."""
    cranks = np.linspace(0.0, 2 * np.pi, 37)[1:]
    sol = linkopt.solve_fk_path(four_bar, cranks[:, None])
    assert bool(np.all(sol.converged))
    return cranks, sol.state


def test_fk_matches_circle_intersection_over_a_full_turn(four_bar, revolution):
    cranks, states = revolution
    rocker = np.asarray(linkopt.output_values(four_bar, states))[:, 0]
    point = np.asarray(linkopt.reported_values(four_bar, states))
    expected = [_pose(c) for c in cranks]
    rocker_error = np.abs(_wrapped(rocker - [e[2] for e in expected])).max()
    point_error = np.abs(point - np.array([e[4] for e in expected])).max()
    assert rocker_error < 1e-9  # measured 4.9e-15 rad
    assert point_error < 1e-8  # measured 2.3e-13 mm
    joints = np.asarray(linkopt.joint_positions(four_bar, states))
    assert np.abs(joints[:, 2, :2] - np.array([e[1] for e in expected])).max() < 1e-8


def test_bk_round_trip_over_the_rocker_range(four_bar):
    targets = np.linspace(-0.2, 0.5, 8)[:, None]
    back = linkopt.solve_bk_path(four_bar, targets)
    assert bool(np.all(back.converged))
    cranks = np.asarray(linkopt.motor_values(four_bar, back.state))[:, 0]
    rockers = np.array([_pose(c)[2] for c in cranks])
    assert np.abs(_wrapped(rockers - targets[:, 0])).max() < 1e-9
    again = linkopt.solve_fk(four_bar, cranks[:, None])
    np.testing.assert_allclose(again.state, back.state, atol=1e-9)


def test_backward_singularity_at_the_toggle_positions(four_bar, revolution):
    cranks, states = revolution
    sigma = np.asarray(linkopt.singular_values(four_bar, states))
    toggle = []
    for crank in cranks:
        b, c, *_ = _pose(crank)
        coupler = np.arctan2(*(c - b)[::-1])
        toggle.append(abs(np.sin(np.pi / 2 + crank - coupler)))
    ratio = sigma[:, 1] / np.array(toggle)
    # σ_min(BK) is the textbook |sin(θ2 - θ3)| times a near-constant (0.189-0.199)
    assert ratio.max() / ratio.min() < 1.1
    assert sigma[:, 0].min() > 0.1  # a crank-rocker has no forward singularity
    # at the extended toggle (|AC| = a + b) σ_min(BK) vanishes
    c = _circles([0.0, 0.0], A + B, [D, 0.0], C)
    crank = np.arctan2(c[1], c[0]) - np.pi / 2
    # with the rest crank in one batch: the block programs of test_reference_values.py
    at = linkopt.solve_fk(four_bar, np.array([[crank % (2 * np.pi)], [0.0]]))
    assert np.all(np.asarray(at.converged))
    fk, bk = np.asarray(linkopt.singular_values(four_bar, at.state))[0]
    assert bk < 1e-6 < 0.1 < fk
