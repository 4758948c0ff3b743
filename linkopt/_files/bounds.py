"""The magnitudes a mechanism file may give, and the reference length ``L``.

Every number is checked for being finite and of a magnitude the solver can work with
before anything is computed from it, so that an absurd value is named where it is
written and never surfaces later as a wrong mobility or a singular rest pose:

* the reference length ``L`` (given, or the span of the joint anchors) lies in
  [1e-12, 1e12] file units, and a given one within a factor 1e3 of the span: the
  solver works on lengths divided by ``L``, and the five-bar's rest check and FK still
  hold at ``L`` = 1e-4 to 1e4 times its span but not at 1e-6 or 1e6 (the rank and
  σ_min tests and the LM tolerance are absolute in homogenised units);
* every position (anchors, body origins, point positions, the symmetry point,
  Cartesian output ranges and anchor-parameter bounds) is at most 1e6 reference
  lengths and 1e12 file units from the world origin in each coordinate: far past any
  real layout (the five-bar still solves 1e8 reference lengths away), far below where
  squares of lengths overflow;
* angle-output ranges lie within ±1e3 rad, axis-parameter bounds within ±1e6 (the axis
  is normalised, so beyond that its direction no longer changes in float64).

Axes and the symmetry normal are directions: any finite non-zero vector is one.
"""

from __future__ import annotations

import numpy as np
from jaxtyping import Float

from .._engine.model import OUTPUT_KINDS
from .fields import Reader

#: Largest |cos| between two axes that must be perpendicular.
ORTHOGONAL_TOL = 1e-9
#: Smallest and largest reference length (file units).
REFERENCE_LENGTHS = (1e-12, 1e12)
#: A given reference length lies within this factor of the joint anchors' span.
SCALE_RATIO = 1e3
#: Largest coordinate of a position: in reference lengths, and in file units.
MAX_EXTENT = 1e6
MAX_COORDINATE = 1e12
#: Largest |bound| of an angle-output range (rad).
MAX_ANGLE = 1e3


def position_limit(scale: float | None) -> tuple[float, str]:
    """The largest coordinate of a position (file units) and how it is worded; before
    the reference length is known (``None``), the absolute bound alone."""
    if scale is None:
        return MAX_COORDINATE, f"{MAX_COORDINATE:g} file units"
    limit = min(MAX_COORDINATE, MAX_EXTENT * scale)
    return limit, (
        f"{limit:g} file units ({MAX_EXTENT:g} reference lengths of {scale:g}, "
        f"at most {MAX_COORDINATE:g})"
    )


def check_position(rd: Reader, where: str, values, scale: float | None) -> None:
    """Coordinates (a number or a vector, file units) within the position bound."""
    limit, words = position_limit(scale)
    largest = float(np.max(np.abs(values)))
    if largest > limit:
        raise rd.fail(
            where, f"expected coordinates of magnitude at most {words}, got {largest:g}"
        )


def position(
    rd: Reader, item: dict, key: str, where: str, scale: float | None
) -> Float[np.ndarray, " 3"]:
    """``item[key]``: a position, 3 finite numbers within the position bound."""
    vec = rd.vector(item, key, where)
    check_position(rd, f"{where}.{key}", vec, scale)
    return vec


def check_value(rd: Reader, where: str, values, kind: str, scale: float) -> None:
    """Values of an output (a length or an angle, :data:`OUTPUT_KINDS`) within its
    bound."""
    if OUTPUT_KINDS[kind]:
        check_position(rd, where, values, scale)
    elif float(np.max(np.abs(values))) > MAX_ANGLE:
        raise rd.fail(
            where,
            f"expected angles of magnitude at most {MAX_ANGLE:g} rad, got "
            f"{float(np.max(np.abs(values))):g}",
        )


def diameter(points: Float[np.ndarray, "N 3"]) -> float:
    """Largest distance between two of ``points (N, 3)``: the default reference length
    (over the joint anchors) and the one the arm builders give for their bodies."""
    points = np.asarray(points, dtype=float)
    return float(np.max(np.linalg.norm(points[:, None] - points[None], axis=-1)))


def reference_length(rd: Reader, head: dict, anchors: np.ndarray) -> float:
    """``[mechanism].reference_length``, else the span of the joint ``anchors``."""
    span = diameter(anchors)
    if "reference_length" in head:
        return _given_reference_length(rd, head, span)
    if span <= 0:
        raise rd.fail(
            "[mechanism].reference_length",
            "all joint anchors coincide; give a positive reference_length",
        )
    if span < REFERENCE_LENGTHS[0]:
        raise rd.fail(
            "[mechanism].reference_length",
            f"the joint anchors span only {span:g} file units, below "
            f"{REFERENCE_LENGTHS[0]:g}; give a reference_length",
        )
    return span


def _given_reference_length(rd: Reader, head: dict, span: float) -> float:
    """``reference_length`` in :data:`REFERENCE_LENGTHS`, within a factor
    :data:`SCALE_RATIO` of the anchors' ``span`` (unless they all coincide)."""
    scale = rd.bounded(head, "reference_length", "[mechanism]", *REFERENCE_LENGTHS)
    if span > 0 and not span / SCALE_RATIO <= scale <= span * SCALE_RATIO:
        raise rd.fail(
            "[mechanism].reference_length",
            f"{scale:g} is not within a factor {SCALE_RATIO:g} of the span of the "
            f"joint anchors ({span:g}); lengths divided by it would be too large or "
            "too small for the solver",
        )
    return scale
