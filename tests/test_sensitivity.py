"""Implicit-function sensitivities ds/da, ds/db, ds/dp against 64-bit finite
differences."""

import numpy as np
import pytest

import linkopt

# Steps: the solves stop at max|C| <= 1e-12, so a step h carries a noise of about
# 1e-12 / h; 1e-5 rad and 1e-3 mm keep both that and the O(h²) truncation below 1e-8.
H_ANGLE = 1e-5
H_LENGTH = 1e-3


def central(fn, x, h):
    x = np.asarray(x, dtype=float)
    cols = [
        (np.asarray(fn(x + h * e)) - np.asarray(fn(x - h * e))) / (2 * h)
        for e in np.eye(x.size)
    ]
    return np.stack(cols, axis=-1)


@pytest.fixture(scope="module")
def solved(five_bar):
    return linkopt.solve_fk(five_bar, np.array([0.3, -0.2])).state


def test_ds_da(five_bar, solved):
    motors = np.asarray(linkopt.motor_values(five_bar, solved))
    exact = np.asarray(linkopt.sensitivity(five_bar, solved, "motors"))
    fd = central(
        lambda a: linkopt.solve_fk(five_bar, a, start=solved).state, motors, H_ANGLE
    )
    assert exact.shape == (35, 2)
    np.testing.assert_allclose(exact, fd, atol=1e-8)
    assert np.abs(exact).max() > 0.1


def test_ds_db(five_bar, solved):
    outputs = np.asarray(linkopt.output_values(five_bar, solved))
    exact = np.asarray(linkopt.sensitivity(five_bar, solved, "outputs"))
    fd = central(
        lambda b: linkopt.solve_bk(five_bar, b, start=solved).state, outputs, H_LENGTH
    )
    np.testing.assert_allclose(exact, fd, atol=1e-8)
    assert np.abs(exact).max() > 1e-3


@pytest.mark.parametrize("wrt, solver", [("design", "fk"), ("design_bk", "bk")])
def test_ds_dp(five_bar, solved, wrt, solver):
    p0 = five_bar.design.p0
    if solver == "fk":
        values = linkopt.motor_values(five_bar, solved)
        fn = lambda p: linkopt.solve_fk(five_bar, values, start=solved, design=p).state  # noqa: E731
    else:
        values = linkopt.output_values(five_bar, solved)
        fn = lambda p: linkopt.solve_bk(five_bar, values, start=solved, design=p).state  # noqa: E731
    exact = np.asarray(linkopt.sensitivity(five_bar, solved, wrt))
    np.testing.assert_allclose(exact, central(fn, p0, H_LENGTH), atol=1e-8)
    assert np.abs(exact).max() > 1e-3
