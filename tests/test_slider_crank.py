"""The offset slider-crank, driven at the crank (``slider_crank.toml``, slider
displacement output) and at the slider (``slider_crank_linear.toml``, crank angle
output), against ``x = r cos θ + sqrt(l² - (r sin θ - e)²)``.

The dead points (crank and rod collinear) are where the textbook Jacobian of the loop
closure in (crank angle θ, rod angle φ) has determinant ``r l sin(θ - φ)`` = 0: a
backward singularity of the crank motor / slider output pair and a forward one of the
slider motor / crank output pair. σ_min of the matching Jacobian follows
``|sin(θ - φ)|``; the other one stays away from zero (the rod never stands
perpendicular to the slide, ``l > r + e``).
"""

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt

R, L, E = 20.0, 60.0, 10.0
REST = np.pi / 2  # crank angle at rest, from the x axis
X0 = np.sqrt(L * L - (R - E) ** 2)


def _slider(theta):
    """Slider position (mm along x) for the crank angle ``theta`` from the x axis."""
    return R * np.cos(theta) + np.sqrt(L * L - (R * np.sin(theta) - E) ** 2)


def _dead_point_measure(theta):
    """``|sin(θ - φ)|`` with ``φ`` the rod angle (crank pin to slider pin)."""
    rod = np.arctan2(E - R * np.sin(theta), _slider(theta) - R * np.cos(theta))
    return np.abs(np.sin(theta - rod))


def _wrapped(angle):
    return (np.asarray(angle) + np.pi) % (2 * np.pi) - np.pi


@pytest.fixture(scope="module")
def rotary():
    return linkopt.load(MECHANISMS / "slider_crank.toml")


@pytest.fixture(scope="module")
def linear():
    return linkopt.load(MECHANISMS / "slider_crank_linear.toml")


CRANKS = np.linspace(0.0, 2 * np.pi, 37)[1:]


def test_rotary_fk_over_a_full_turn_and_its_dead_points(rotary):
    sol = linkopt.solve_fk_path(rotary, CRANKS[:, None])
    assert bool(np.all(sol.converged))
    slide = np.asarray(linkopt.output_values(rotary, sol.state))[:, 0]
    error = np.abs(slide - (_slider(REST + CRANKS) - X0)).max()
    assert error < 1e-9  # measured 1.8e-14 mm
    pin = np.asarray(linkopt.reported_values(rotary, sol.state))
    circle = R * np.stack([np.cos(REST + CRANKS), np.sin(REST + CRANKS)], 1)
    assert np.abs(pin - circle).max() < 1e-9
    fk, bk = np.asarray(linkopt.singular_values(rotary, sol.state)).T
    ratio = bk / _dead_point_measure(REST + CRANKS)
    assert ratio.max() / ratio.min() < 1.2  # measured 1.12
    assert fk.min() > 0.05


def test_rotary_bk_round_trip(rotary):
    targets = np.linspace(-12.0, 12.0, 7)[:, None]
    back = linkopt.solve_bk_path(rotary, targets)
    assert bool(np.all(back.converged))
    crank = np.asarray(linkopt.motor_values(rotary, back.state))[:, 0]
    assert np.abs(_slider(REST + crank) - X0 - targets[:, 0]).max() < 1e-9
    again = linkopt.solve_fk(rotary, crank[:, None])
    np.testing.assert_allclose(again.state, back.state, atol=1e-9)


def test_linear_motor_variant_bk_over_a_full_turn_and_its_dead_points(linear):
    back = linkopt.solve_bk_path(linear, CRANKS[:, None])
    assert bool(np.all(back.converged))
    motor = np.asarray(linkopt.motor_values(linear, back.state))[:, 0]
    assert np.abs(motor - (_slider(REST + CRANKS) - X0)).max() < 1e-9
    fk, bk = np.asarray(linkopt.singular_values(linear, back.state)).T
    ratio = fk / _dead_point_measure(REST + CRANKS)
    assert ratio.max() / ratio.min() < 1.2  # measured 1.12
    assert bk.min() > 0.05
    # FK from the slider positions gives the crank angles back (inside the dead
    # points, on the rest branch)
    inside = np.linspace(-0.8, 0.8, 5)
    fk_sol = linkopt.solve_fk_path(linear, (_slider(REST + inside) - X0)[:, None])
    assert bool(np.all(fk_sol.converged))
    crank = np.asarray(linkopt.output_values(linear, fk_sol.state))[:, 0]
    assert np.abs(_wrapped(crank - inside)).max() < 1e-9
