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
to rounding (``tests/test_turns.py``).

Two ways of applying them (:attr:`Turn.unrolled`, static). The contractions
(``einsum``) are one operation each, the fewest to trace and compile; XLA:CPU runs each
as a dot operation of its own, outside the fused element-wise code around it, which
made the solves' batched normal equations 10-40 % slower than with the quaternion
formula (``sum`` of products is slower still). Unrolled, ``R v`` is
``Σ_j R[:, j] v_j`` written out (columns split once per :class:`Side`, a vector's
entries once per vector): element-wise code that XLA fuses, as fast as the formula,
at about five operations per contraction. The normal equations of the solves
(:func:`.jacobian.normal_equations`, the hot path) are built unrolled, the other
Jacobians (σ_min's, the derivatives') with the contractions: the five-bar's evaluation
traces 6.7k equations instead of 6.2k (Stewart's 12.3k instead of 11.4k), with the same
compile time within the noise of a loaded machine.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _config  # noqa: F401  (float64 on before any array)
from .rotations import QUADRATIC, quadratic_matrix
from .row_algebra import take

#: ``∂R/∂q = q · _SLOPES``: ``(4, 36)``, index ``(j, i, a)`` of ``∂R_ij/∂q_a``
#: (column ``j`` of ``R`` first: see :class:`Turn`).
_SLOPES = (2.0 * QUADRATIC).transpose(3, 1, 0, 2).reshape(4, 36).copy()


@dataclass(frozen=True)
class Turn:
    """Rotation matrices ``(..., 3, 3)`` of a set of bodies and their derivatives
    ``(..., 3, 12)``, column by column of ``R``: ``slope[..., j, 4 i + a] =
    ∂R_ij/∂q_a``. ``unrolled`` (static) picks how a :class:`Side` applies them
    (module docstring)."""

    matrix: Float[Array, "... 3 3"]
    slope: Float[Array, "... 3 12"]
    unrolled: bool = False


def body_turns(q: Float[Array, "B 4"], unrolled: bool = False) -> Turn:
    """The :class:`Turn` of every body from its quaternion (homogeneous, any norm)."""
    slope = (q @ jnp.asarray(_SLOPES)).reshape(q.shape[:-1] + (3, 12))
    return Turn(quadratic_matrix(q), slope, unrolled)


def take_turn(turn: Turn, index: np.ndarray) -> Turn:
    """The turns of bodies ``index`` (static), along axis 0."""
    return Turn(take(turn.matrix, index), take(turn.slope, index), turn.unrolled)


def turned(turn: Turn, v: Float[Array, "... 3"]) -> Float[Array, "... 3"]:
    """``R v`` (:func:`.rotations.rotate` of the body's quaternion and ``v``)."""
    return Side(turn).rot(v)


def turned_slope(turn: Turn, v: Float[Array, "... 3"]) -> Float[Array, "... 3 4"]:
    """``∂(R v)/∂q`` for ``v`` held fixed."""
    return Side(turn).slope(v)


def _parts(v: Float[Array, "... 3"]) -> tuple:
    """The three entries of ``v``, ``(..., 1)`` each."""
    return tuple(v[..., j : j + 1] for j in range(3))


def _combine(columns: tuple, parts: tuple):
    """``Σ_j columns[j] parts[j]``, unrolled."""
    return columns[0] * parts[0] + columns[1] * parts[1] + columns[2] * parts[2]


def _columns(matrix: Float[Array, "... k 3"]) -> tuple:
    """The three columns (last axis) of ``matrix``, ``(..., k)`` each."""
    return tuple(matrix[..., j] for j in range(3))


class Side:
    """One side (``i`` or ``j``) of a group of joints: the gathered turns of its
    bodies and, per body-local vector asked for, its rotation and slope, each built
    once per trace (a joint family asks for ``R_i n`` in several rows). Unrolled
    (:attr:`Turn.unrolled`), the columns of the turns are split once per side and
    the entries of a vector once per vector."""

    def __init__(self, turn: Turn):
        self.turn = turn
        # [v, its entries or None, R v, flat ∂(R v)/∂q, the same (G, 3, 4)]
        self._made: list[list] = []
        self._parts: list[tuple] = []  # (a, its entries) of the vectors dotted with
        self._split: tuple | None = None  # unrolled: (columns of R, of the slope)

    def _columns(self) -> tuple:
        if self._split is None:
            self._split = (_columns(self.turn.matrix), _slope_columns(self.turn))
        return self._split

    def _find(self, v) -> list:
        for made in self._made:
            if made[0] is v:
                return made
        if self.turn.unrolled:
            parts = _parts(v)
            rotated = _combine(self._columns()[0], parts)
        else:
            parts, rotated = None, jnp.einsum("...ij,...j->...i", self.turn.matrix, v)
        self._made.append([v, parts, rotated, None, None])
        return self._made[-1]

    def _flat_slope(self, v) -> Float[Array, "G 12"]:
        made = self._find(v)
        if made[3] is None:
            if self.turn.unrolled:
                made[3] = _combine(self._columns()[1], made[1])
            else:
                made[3] = jnp.einsum("...jk,...j->...k", self.turn.slope, v)
        return made[3]

    def _parts_of(self, a) -> tuple:
        for known, parts in self._parts:
            if known is a:
                return parts
        self._parts.append((a, _parts(a)))
        return self._parts[-1][1]

    def rot(self, v: Float[Array, "G 3"]) -> Float[Array, "G 3"]:
        """``R v`` per member."""
        return self._find(v)[2]

    def slope(self, v: Float[Array, "G 3"]) -> Float[Array, "G 3 4"]:
        """``∂(R v)/∂q`` per member."""
        made = self._find(v)
        if made[4] is None:
            flat = self._flat_slope(v)
            made[4] = flat.reshape(flat.shape[:-1] + (3, 4))
        return made[4]

    def dot_grad(self, v: Float[Array, "G 3"], a: Float[Array, "G 3"]):
        """``∂(a · R v)/∂q`` for ``a`` held fixed, ``(G, 4)``."""
        if not self.turn.unrolled:
            return jnp.einsum("...i,...ia->...a", a, self.slope(v))
        flat = self._flat_slope(v)
        rows = tuple(flat[..., 4 * i : 4 * i + 4] for i in range(3))
        return _combine(rows, self._parts_of(a))


def _slope_columns(turn: Turn) -> tuple:
    """``∂R[:, j]/∂q`` flattened to ``(..., 12)`` (index ``4 i + a``), per ``j``."""
    return tuple(turn.slope[..., j, :] for j in range(3))
