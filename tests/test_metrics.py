"""φ, ψ and the barrier of App. A/B: values, C² joins, the minimum of ψ at α_t."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from linkopt._design.metrics import attractive, barrier, culled, step, thresholds

TH = thresholds(7.0)  # α₋ = 7, α₊ = 10, α_t = 8.5


def derivatives(fn, x):
    d1 = jax.grad(fn)
    d2 = jax.grad(d1)
    return fn(x), d1(x), d2(x)


def test_thresholds_follow_the_paper():
    assert float(TH.upper) == pytest.approx(10.0)
    assert float(TH.target) == pytest.approx(8.5)


def test_step_values_and_c2_joins():
    def phi(x):
        return step(x, TH)

    assert (
        float(phi(6.0)) == 0.0
        and float(phi(11.0)) == 1.0
        and float(phi(8.5)) == pytest.approx(0.5)
    )
    for join in (7.0, 10.0):
        left = np.array(derivatives(phi, join - 1e-7))
        right = np.array(derivatives(phi, join + 1e-7))
        np.testing.assert_allclose(left, right, atol=1e-5)
    assert float(derivatives(phi, 8.5)[1]) == pytest.approx(
        15.0 / 8.0 / 3.0
    )  # 30 X²(1-X)²/Δ at X = ½


def test_culled_is_zero_below_and_identity_above():
    assert float(culled(6.9, TH)) == 0.0
    assert float(culled(12.0, TH)) == 12.0
    assert 0.0 < float(culled(8.0, TH)) < 8.0


def test_attractive_cubic_matches_the_papers_coefficients():
    au, at = 10.0, 8.5
    gap2 = (au - at) ** 2
    a, b, c, d = -1 / (3 * gap2), au / gap2, 1 - au**2 / gap2, au**3 / (3 * gap2)
    for x in (0.0, 3.0, 8.5, 9.9):
        assert float(attractive(x, TH)) == pytest.approx(
            a * x**3 + b * x**2 + c * x + d, rel=1e-12
        )
    assert float(attractive(12.0, TH)) == 12.0


def test_attractive_is_c2_at_alpha_plus_with_minimum_at_alpha_t():
    def psi(x):
        return attractive(x, TH)

    left = np.array(derivatives(psi, 10.0 - 1e-7))
    right = np.array(derivatives(psi, 10.0 + 1e-7))
    np.testing.assert_allclose(left, right, atol=1e-5)
    value, slope, curvature = derivatives(psi, 8.5)
    assert abs(float(slope)) < 1e-12 and float(curvature) > 0
    assert float(psi(8.0)) > float(value) and float(psi(9.0)) > float(value)


def test_barrier_takes_M_on_the_bound_and_m_at_epsilon():
    low, high = jnp.array([0.0]), jnp.array([10.0])
    far = 5.0  # both barriers negligible in the middle
    assert float(barrier(jnp.array([far]), low, high)) < 1e-20
    on_bound = float(barrier(jnp.array([0.0]), low, high))
    at_eps = float(barrier(jnp.array([0.3]), low, high))
    assert on_bound == pytest.approx(5.0, rel=1e-9)
    assert at_eps == pytest.approx(0.1, rel=1e-9)
    assert np.isfinite(float(barrier(jnp.array([-1e6]), low, high)))
