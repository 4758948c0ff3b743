"""What every design-parameter reader shares (:mod:`.design_kinds`,
:mod:`.design_angles`): its context, the anchor and axis moves a
parameter makes per unit change, the parameter record, the symmetric copies it names,
and the checks of its bounds.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from .._engine.symmetry import MIRROR_TOL, Symmetry
from .fields import Reader, shown

#: Largest |bound| of an axis-component parameter (the axis is normalised).
MAX_AXIS_BOUND = 1e6
#: How far (relative to the bounds' magnitude) a rest value may lie outside its bounds
#: and count as on them: the round-off of a design written at a bound.
BOUND_ROUND_OFF = 1e-12
#: The parts a parameter moves: a joint anchor, a joint axis, a named point (whose
#: ``Move.joint`` is then the point's index).
ANCHOR, AXIS, POINT = 0, 1, 2


@dataclass(frozen=True)
class Context:
    """What every parameter reader needs: the joints, the symmetry, the scale."""

    rd: Reader
    joints: list[dict]
    joint_index: dict[str, int]
    body_index: dict[str, int]
    symmetry: Symmetry | None
    scale: float
    check_position: Callable[[str, object], None]
    axis_lengths: np.ndarray  # (J,) length of each joint's axis as the file writes it
    points: tuple[dict, ...] = ()  # the named points as read (points.read_points)
    ground: int = -1  # the ground body

    @property
    def tol(self) -> float:
        return MIRROR_TOL * self.scale

    def anchor(self, j: int) -> np.ndarray:
        return self.joints[j]["anchor"]

    def name(self, j: int) -> str:
        return self.joints[j]["name"]

    def coincident(self, j: int) -> list[int]:
        """The joints whose rest anchor is that of joint ``j`` (``j`` included)."""
        return [
            i
            for i, other in enumerate(self.joints)
            if np.linalg.norm(other["anchor"] - self.anchor(j)) <= self.tol
        ]

    def coincident_all(self, joints: list[int]) -> list[int]:
        """The joints sharing a rest anchor with any of ``joints``, sorted."""
        return sorted({i for j in joints for i in self.coincident(j)})


@dataclass(frozen=True)
class Move:
    """Joint ``joint``'s anchor (``part`` ANCHOR) or axis (AXIS) moves by ``vector``
    per unit of the parameter."""

    joint: int
    part: int
    vector: np.ndarray


@dataclass(frozen=True)
class Parameter:
    value: float
    low: float
    high: float
    is_length: bool
    moves: list[Move]
    links: list[tuple[int, list[int]]]  # length: (from joint, to joints), copies too
    turns: tuple = ()  # twist: its design_angles.Turn


def copies_list(ctx: Context, item: dict, where: str) -> list:
    """``copies``: a non-empty list of at most ``size - 1`` entries, with a
    ``[symmetry]``."""
    rd, value = ctx.rd, item["copies"]
    if ctx.symmetry is None:
        raise rd.fail(f"{where}.copies", "copies need a [symmetry] table")
    most = ctx.symmetry.size - 1
    if not isinstance(value, list) or not 1 <= len(value) <= most:
        raise rd.fail(
            f"{where}.copies",
            f"expected a list of 1 to {most} names (images under the "
            f"{ctx.symmetry.kind} symmetry), got {shown(value)}",
        )
    return value


def bounds(
    rd: Reader, item: dict, where: str, value: float, label: str
) -> tuple[float, float]:
    """``min < max``, with the rest value between them (or within round-off of a
    bound: a design written at its bound reads back, :func:`read_parameter` puts it
    on the bound)."""
    low, high = rd.number(item, "min", where), rd.number(item, "max", where)
    if not low < high:
        raise rd.fail(
            f"{where}.min", f"bounds need min < max, got min={low} and max={high}"
        )
    slack = BOUND_ROUND_OFF * max(1.0, abs(low), abs(high))
    if not low - slack <= value <= high + slack:
        raise rd.fail(
            f"{where}.{'min' if value < low else 'max'}",
            f"the rest value {value:g} of {label} lies outside [{low:g}, {high:g}]",
        )
    return low, high


def positive_bounds(
    ctx: Context, item: dict, where: str, value: float, label: str
) -> tuple[float, float]:
    """Bounds of a length or radius: positive (at zero the direction is lost), within
    the position bound, around the rest value."""
    low, high = bounds(ctx.rd, item, where, value, f"the {label}")
    if low <= 0:
        raise ctx.rd.fail(f"{where}.min", f"a {label} needs min > 0, got min={low:g}")
    ctx.check_position(f"{where}.max", (low, high))
    return low, high


def check_bound_magnitude(
    ctx: Context, where: str, bounds: tuple[float, float], part: int
) -> None:
    """Anchor-parameter bounds are positions; axis-component ones at most
    :data:`MAX_AXIS_BOUND`. The larger bound in magnitude is the one named."""
    where = f"{where}.{'min' if abs(bounds[0]) >= abs(bounds[1]) else 'max'}"
    if part == ANCHOR:
        ctx.check_position(where, bounds)
    elif max(abs(b) for b in bounds) > MAX_AXIS_BOUND:
        raise ctx.rd.fail(
            where,
            f"expected axis-component bounds of magnitude at most {MAX_AXIS_BOUND:g}, "
            f"got min={bounds[0]:g} and max={bounds[1]:g}",
        )
