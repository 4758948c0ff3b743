"""Each body's rotation matrix and its quaternion derivative, built once per state and
applied to every body-local vector of the constraint rows' Jacobian
(:mod:`.jacobian`), instead of rotating vector by vector with the quaternion formula.

``R(q)`` is the quadratic form of :func:`.rotations.rotate`, ``R(q) v = rotate(q, v)``
for any ``q`` (for a non-unit ``q`` it is ``|q|²`` times a rotation, as the solver's
states are), so its entries are ``R_ij = qᵀ Q_ij q`` with constant symmetric
``4 x 4`` matrices ``Q_ij`` (:data:`.rotations.QUADRATIC`) and its derivative is
``∂R_ij/∂q = 2 Q_ij q``.
Per body that is one product with a constant matrix each; per member of a row group a
rotated vector is one contraction ``R v`` and ``∂(R v)/∂q`` one more, where the
quaternion formula traced some forty operations (products, crosses, unrolled dots):
the programs that hold the Jacobian (the evaluation, its derivative in the state)
trace and compile that much less (``benchmarks/program_size.py``: Stewart's evaluation
28.3k → 9.9k equations, 24 → 12 s compile CPU). Equal to the quaternion formulas up
to rounding (``tests/test_turns.py``). The contractions are ``einsum`` (batched dots):
measured on a loaded 2-core machine, the Jansen leg's batched normal equations took
10-20 % more CPU than with the formula, the five-bar's the same; ``sum`` of products
instead of ``einsum`` was slower still.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _config  # noqa: F401  (float64 on before any array)
from .rotations import QUADRATIC, quadratic_matrix
from .row_algebra import take

#: ``∂R/∂q = q · _SLOPES``: ``(4, 36)``, index ``(i, j, a)`` of ``∂R_ij/∂q_a``.
_SLOPES = (2.0 * QUADRATIC).transpose(3, 0, 1, 2).reshape(4, 36).copy()


@dataclass(frozen=True)
class Turn:
    """Rotation matrices ``(..., 3, 3)`` and their derivatives ``(..., 3, 3, 4)``
    (``[..., i, j, a] = ∂R_ij/∂q_a``) of a set of bodies."""

    matrix: Float[Array, "... 3 3"]
    slope: Float[Array, "... 3 3 4"]


def body_turns(q: Float[Array, "B 4"]) -> Turn:
    """The :class:`Turn` of every body from its quaternion (homogeneous, any norm)."""
    slope = (q @ jnp.asarray(_SLOPES)).reshape(q.shape[:-1] + (3, 3, 4))
    return Turn(quadratic_matrix(q), slope)


def take_turn(turn: Turn, index: np.ndarray) -> Turn:
    """The turns of bodies ``index`` (static), along axis 0."""
    return Turn(take(turn.matrix, index), take(turn.slope, index))


def turned(turn: Turn, v: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """``R v`` (:func:`.rotations.rotate` of the body's quaternion and ``v``)."""
    return jnp.einsum("...ij,...j->...i", turn.matrix, v)


def turned_slope(turn: Turn, v: Float[Array, "... 3"]) -> Float[Array, "... 3 4"]:
    """``∂(R v)/∂q`` for ``v`` held fixed."""
    return jnp.einsum("...ija,...j->...ia", turn.slope, v)


def along(a: Float[Array, "... 3"], slope: Float[Array, "... 3 4"]):
    """``a · ∂(R v)/∂q`` from ``slope`` = :func:`turned_slope`: ``∂(a · R v)/∂q`` for
    ``a`` held fixed, shape ``(..., 4)``."""
    return jnp.einsum("...i,...ia->...a", a, slope)


class Side:
    """One side (``i`` or ``j``) of a group of joints: the gathered turns of its
    bodies and, per body-local vector asked for, its rotation and slope, each built
    once per trace (a joint family asks for ``R_i n`` in several rows)."""

    def __init__(self, turn: Turn):
        self.turn = turn
        self._made: list[tuple] = []  # (v, R v, ∂(R v)/∂q or None)

    def _find(self, v):
        for k, (known, *_) in enumerate(self._made):
            if known is v:
                return k
        self._made.append((v, turned(self.turn, v), None))
        return len(self._made) - 1

    def rot(self, v: Float[Array, "G 3"]) -> Float[Array, "G 3"]:
        """``R v`` per member."""
        return self._made[self._find(v)][1]

    def slope(self, v: Float[Array, "G 3"]) -> Float[Array, "G 3 4"]:
        """``∂(R v)/∂q`` per member."""
        k = self._find(v)
        known, rotated, slope = self._made[k]
        if slope is None:
            slope = turned_slope(self.turn, v)
            self._made[k] = (known, rotated, slope)
        return slope

    def dot_grad(self, v: Float[Array, "G 3"], a: Float[Array, "G 3"]):
        """``∂(a · R v)/∂q`` for ``a`` held fixed, ``(G, 4)``."""
        return along(a, self.slope(v))
