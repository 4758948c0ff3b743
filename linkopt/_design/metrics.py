"""Culled and attractive singularity metrics and the adversarial barrier (paper App. A,
B).

* ``φ`` (eq. 7): C² quintic step from 0 at ``α₋`` to 1 at ``α₊``; culled
  ``f_sing^c = f_sing · φ(f_sing)``.
* ``ψ`` (eq. 8): identity above ``α₊``, below it the cubic with
  ``ψ'(x) = 1 - (x - α₊)² / (α₊ - α_t)²``: C² at ``α₊`` and a local minimum at
  ``α_t = (α₋ + α₊)/2``; attractive ``f_sing^a = ψ(f_sing)``.
* ``β₋, β₊`` (eq. 10): exponential barriers equal to ``M`` on the range bound and ``m``
  at ``ε`` inside it; ``R₂`` (eq. 9) sums them over outputs.

``α₊ = 10/7 α₋`` as in the paper.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
from jaxtyping import Array, Float

from .. import _config  # noqa: F401  (float64 on before any array)

ALPHA_PLUS_RATIO = 10.0 / 7.0
BARRIER_LOW = 0.1  # m
BARRIER_HIGH = 5.0  # M
BARRIER_WIDTH = 0.03  # ε as a fraction of each output's range


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Thresholds:
    """``α₋ < α_t < α₊`` of App. A."""

    lower: Float[Array, ""]
    target: Float[Array, ""]
    upper: Float[Array, ""]


def thresholds(alpha_minus) -> Thresholds:
    alpha_minus = jnp.asarray(alpha_minus, dtype=jnp.float64)
    upper = ALPHA_PLUS_RATIO * alpha_minus
    return Thresholds(alpha_minus, 0.5 * (alpha_minus + upper), upper)


def step(x: Float[Array, ...], th: Thresholds) -> Float[Array, ...]:
    """``φ(x)`` of eq. 7."""
    t = jnp.clip((x - th.lower) / (th.upper - th.lower), 0.0, 1.0)
    return t * t * t * (t * (6.0 * t - 15.0) + 10.0)


def culled(f_sing: Float[Array, ...], th: Thresholds) -> Float[Array, ...]:
    """``f_sing^c = f_sing · φ(f_sing)``: zero below ``α₋``, ``f_sing`` above ``α₊``."""
    return f_sing * step(f_sing, th)


def attractive(f_sing: Float[Array, ...], th: Thresholds) -> Float[Array, ...]:
    """``f_sing^a = ψ(f_sing)`` of eq. 8."""
    gap2 = (th.upper - th.target) ** 2
    a = -1.0 / (3.0 * gap2)
    b = th.upper / gap2
    c = 1.0 - th.upper**2 / gap2
    d = th.upper**3 / (3.0 * gap2)
    x = jnp.minimum(f_sing, th.upper)  # keep the unused branch finite for AD
    cubic = ((a * x + b) * x + c) * x + d
    return jnp.where(f_sing < th.upper, cubic, f_sing)


def barrier(
    values: Float[Array, " K"], low: Float[Array, " K"], high: Float[Array, " K"]
) -> Float[Array, ""]:
    """``R₂`` of eq. 9-10 with ``m = 0.1``, ``M = 5``, ``ε = 0.03 (max - min)``."""
    width = BARRIER_WIDTH * (high - low)
    rate = jnp.log(BARRIER_LOW / BARRIER_HIGH) / width
    # exponents capped so a sample far outside the range gives a large, finite barrier
    below = BARRIER_HIGH * jnp.exp(jnp.minimum(rate * (values - low), 50.0))
    above = BARRIER_HIGH * jnp.exp(jnp.minimum(rate * (high - values), 50.0))
    return jnp.sum(below + above)
