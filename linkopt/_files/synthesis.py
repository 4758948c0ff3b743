"""The ``[synthesis]`` table of a mechanism file and target CSV files.

A synthesis target is a path of a named point, a function of a named output or the
poses of a named body (:class:`Targets`). It is read here, as every table of a file
is (:mod:`linkopt._files`), with the checks that need nothing but the file's names:
the count of rows, finite and distinct rows, unit quaternions, names the file
defines. The checks that need the mechanism's geometry (reach, a full-turn crank,
motor ranges) are :func:`linkopt._synth.targets.check_targets`.

``[synthesis]`` fields (file units, radians)::

    kind = "path"              # "path" | "function" | "motion"
    name = "coupler_point"     # a [[points]] name, an [[outputs]] name, a body name
    points = [[x, y], ...]     # path: x, y[, z]; function: input, output;
                               # motion: x, y, z, qw, qx, qy, qz
    file = "curve.csv"         # instead of points: a CSV beside the mechanism file
    motors = [[a], ...]        # optional timing: motor values at each row
    closed = false             # optional: one full motor turn returns to the start
    tolerance = 0.5            # largest allowed distance to each target
    min_transmission_deg = 30  # optional: least transmission angle of a planar
                               # four-bar over its cycle (0: not asked)

A CSV has a header row naming its columns: ``x, y[, z]`` for a path, the motor's and
the output's names for a function, ``x, y, z, qw, qx, qy, qz`` for a motion; a column
named after a motor gives the timing of a path or a motion.
"""

from __future__ import annotations

import csv
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .._errors import MechanismFileError
from .fields import Reader, is_finite_number, shown

KINDS = ("path", "function", "motion")
FIELDS = {
    "kind",
    "name",
    "points",
    "file",
    "motors",
    "closed",
    "tolerance",
    "min_transmission_deg",
}
#: The least transmission angle a planar four-bar's cycle keeps unless the table
#: says otherwise (degrees; a common design rule asks 40).
MIN_TRANSMISSION_DEG = 30.0
POSE_COLUMNS = ("x", "y", "z", "qw", "qx", "qy", "qz")
#: Fewest rows of each kind (a closed path needs three to enclose anything).
FEWEST = {"path": 2, "function": 2, "motion": 2}
FEWEST_CLOSED = 3
#: Two rows closer than this (relative to the rows' spread) are one point.
DUPLICATE = 1e-9
#: How far from 1 a quaternion's norm may be.
UNIT_SLACK = 1e-6


@dataclass(frozen=True)
class Targets:
    """A synthesis target (the synthesis contract). ``values``: path ``(k, 3)``
    positions in file units; function ``(k,)`` output values; motion ``(k, 7)``
    position then unit quaternion ``(w, x, y, z)``. ``motors``: ``(k, M)`` motor
    values at each target (timing), or None (free). ``closed``: one full motor turn
    returns to the start. ``tolerance``: largest allowed distance to each target
    (file units; rad for angles). ``min_transmission_deg``: the least transmission
    angle over the cycle of a planar four-bar (degrees; 0: not asked; other
    mechanisms ignore it)."""

    kind: str
    name: str
    values: np.ndarray
    motors: np.ndarray | None
    closed: bool
    tolerance: float
    source: str = ""  # the file (and field) the targets were read from, for messages
    min_transmission_deg: float = MIN_TRANSMISSION_DEG

    @property
    def count(self) -> int:
        return len(self.values)


@dataclass(frozen=True)
class Names:
    """The names a target may refer to, from the mechanism file."""

    motors: tuple[str, ...]
    points: tuple[str, ...]
    outputs: tuple[str, ...]
    bodies: tuple[str, ...]

    def of(self, kind: str) -> tuple[str, tuple[str, ...]]:
        """What a target of ``kind`` names, and the names the file defines."""
        return {
            "path": ("[[points]]", self.points),
            "function": ("[[outputs]]", self.outputs),
            "motion": ("[[bodies]]", self.bodies),
        }[kind]


def synthesis_names(mech) -> Names:
    """The names a target of the mechanism ``mech`` may refer to."""
    return Names(
        motors=tuple(mech.motor_names),
        points=tuple(mech.point_names),
        outputs=tuple(mech.output_names),
        bodies=tuple(mech.body_names),
    )


def read_synthesis(source: str, table, names: Names) -> Targets:
    """The targets of a file's ``[synthesis]`` table (module docstring)."""
    rd, where = Reader(source), "[synthesis]"
    table = rd.table(table, where, FIELDS, {"kind", "name", "tolerance"})
    kind = _kind(rd, table, where)
    name = _name(rd, table, where, kind, names)
    if ("points" in table) == ("file" in table):
        raise rd.fail(f"{where}.points", "give either points or file (one of them)")
    if "file" in table:
        csv_path = Path(source).parent / rd.string(table, "file", where)
        rows, motors = read_rows(csv_path, kind, name, names)
        at = str(csv_path)
    else:
        rows = _matrix(rd, table, "points", where)
        motors, at = None, f"{where}.points"
    if "motors" in table:
        if motors is not None:
            raise rd.fail(f"{where}.motors", "the CSV file already gives the timing")
        motors = _matrix(rd, table, "motors", where)
        _width(rd, f"{where}.motors", motors, len(names.motors), "motor values")
    closed = rd.boolean(table, "closed", where) if "closed" in table else False
    tolerance = rd.positive(table, "tolerance", where)
    least = _least_transmission(rd, table, where)
    return build(source, at, kind, name, rows, motors, closed, tolerance, least)


def _least_transmission(rd: Reader, table: dict, where: str) -> float:
    if "min_transmission_deg" not in table:
        return MIN_TRANSMISSION_DEG
    value = table["min_transmission_deg"]
    if not is_finite_number(value) or not 0.0 <= float(value) < 90.0:
        raise rd.fail(
            f"{where}.min_transmission_deg",
            f"expected a number of degrees in [0, 90), got {shown(value)}",
        )
    return float(value)


def _kind(rd: Reader, table: dict, where: str) -> str:
    kind = rd.string(table, "kind", where)
    if kind not in KINDS:
        raise rd.fail(f"{where}.kind", f"expected one of {list(KINDS)}, got {kind!r}")
    return kind


def _name(rd: Reader, table: dict, where: str, kind: str, names: Names) -> str:
    name = rd.string(table, "name", where)
    what, known = names.of(kind)
    if name not in known:
        raise rd.fail(
            f"{where}.name",
            f"a {kind} target names one of {what} {list(known)}, got {name!r}",
        )
    return name


def _matrix(rd: Reader, table: dict, key: str, where: str) -> np.ndarray:
    """A list of rows of finite numbers, all of one length."""
    rows = table[key]
    ok = isinstance(rows, list) and all(isinstance(r, list) and r for r in rows)
    if not ok or len({len(r) for r in rows}) > 1:
        raise rd.fail(
            f"{where}.{key}",
            f"expected a list of rows of numbers, all of one length, got {shown(rows)}",
        )
    for k, row in enumerate(rows):
        for value in row:
            if not is_finite_number(value):
                raise rd.fail(
                    f"{where}.{key}[{k}]",
                    f"expected finite numbers, got {shown(value)}",
                )
    return np.asarray(rows, dtype=float).reshape(len(rows), -1)


def _width(rd: Reader, at: str, rows: np.ndarray, width: int, what: str) -> None:
    if rows.shape[1] != width:
        raise rd.fail(at, f"expected {width} {what} per row, got {rows.shape[1]}")


def read_rows(
    path: Path, kind: str, name: str, names: Names
) -> tuple[np.ndarray, np.ndarray | None]:
    """A target CSV's rows (the layout of ``[synthesis].points``) and its timing
    columns (None when it has none); :class:`MechanismFileError` naming the file and
    column."""
    rd, source = Reader(str(path)), str(path)
    try:
        with open(path, newline="") as handle:
            table = [row for row in csv.reader(handle) if row]
    except OSError as error:
        raise MechanismFileError(source, "", f"cannot read: {error.strerror}") from None
    if not table:
        raise rd.fail("header", "empty file; expected a header row naming the columns")
    header = [h.strip() for h in table[0]]
    numbers = [_numbers(rd, k + 2, row, len(header)) for k, row in enumerate(table[1:])]
    data = np.asarray(numbers, dtype=float).reshape(len(numbers), len(header))
    columns = _value_columns(rd, kind, name, header, names)
    timing = [c for c in header if c in names.motors]
    unknown = [c for c in header if c not in (*columns, *timing)]
    if unknown:
        raise rd.fail(
            f"column {unknown[0]!r}",
            f"unknown column; a {kind} target has {list(columns)} and motor timing "
            f"columns {list(names.motors)}",
        )
    pick = [header.index(c) for c in columns]
    if kind == "function":
        return data[:, pick[1]], data[:, [pick[0]]]
    motors = _timing(rd, header, timing, data, names)
    return data[:, pick], motors


def _numbers(rd: Reader, line: int, row: list[str], width: int) -> list[float]:
    if len(row) != width:
        raise rd.fail(f"line {line}", f"expected {width} columns, got {len(row)}")
    try:
        return [float(v) for v in row]
    except ValueError:
        raise rd.fail(f"line {line}", f"expected numbers, got {row}") from None


def _value_columns(
    rd: Reader, kind: str, name: str, header: list[str], names: Names
) -> tuple[str, ...]:
    """The columns that give the target values, in the layout of ``points``."""
    if kind == "function":
        if len(names.motors) != 1:
            raise rd.fail("header", "a function target needs a one-motor mechanism")
        wanted: tuple[str, ...] = (names.motors[0], name)
    elif kind == "motion":
        wanted = POSE_COLUMNS
    else:
        wanted = ("x", "y", "z") if "z" in header else ("x", "y")
    missing = [c for c in wanted if c not in header]
    if missing:
        raise rd.fail(
            f"column {missing[0]!r}",
            f"missing; a {kind} target needs the columns {list(wanted)}",
        )
    return wanted


def _timing(rd, header, timing, data, names: Names) -> np.ndarray | None:
    if not timing:
        return None
    if len(timing) != len(names.motors):
        missing = [m for m in names.motors if m not in timing]
        raise rd.fail(f"column {missing[0]!r}", "missing; timing needs every motor")
    return data[:, [header.index(m) for m in names.motors]]


def build(
    source: str,
    at: str,
    kind: str,
    name: str,
    rows: np.ndarray,
    motors: np.ndarray | None,
    closed: bool,
    tolerance: float,
    min_transmission_deg: float = MIN_TRANSMISSION_DEG,
) -> Targets:
    """:class:`Targets` from rows in the layout of ``[synthesis].points``, checked for
    what needs no geometry (module docstring); ``at`` names the field or file of the
    rows in messages."""
    rd = Reader(source)
    rows = np.asarray(rows, dtype=float)
    if kind == "function" and rows.ndim == 2 and motors is None:
        _width(rd, at, rows, 2, "numbers (input, output)")
        rows, motors = rows[:, 1], rows[:, :1]
    if kind == "path" and rows.ndim == 2 and rows.shape[1] == 2:
        rows = np.column_stack([rows, np.zeros(len(rows))])
    _check_rows(rd, at, kind, rows, closed)
    if motors is not None:
        motors = np.asarray(motors, dtype=float).reshape(len(motors), -1)
        if len(motors) != len(rows):
            raise rd.fail(
                at, f"{len(rows)} targets but {len(motors)} rows of motor timing"
            )
        if not np.all(np.isfinite(motors)):
            raise rd.fail(at, "the motor timing has a value that is not finite")
    return Targets(
        kind,
        name,
        rows,
        motors,
        bool(closed),
        float(tolerance),
        at,
        float(min_transmission_deg),
    )


def _check_rows(rd: Reader, at: str, kind: str, rows: np.ndarray, closed) -> None:
    width = {"path": 3, "motion": 7}.get(kind)
    if width is not None and (rows.ndim != 2 or rows.shape[1] != width):
        what = "x, y[, z]" if kind == "path" else "x, y, z, qw, qx, qy, qz"
        raise rd.fail(at, f"expected rows of {what}, got shape {rows.shape}")
    fewest = FEWEST_CLOSED if closed else FEWEST[kind]
    if len(rows) < fewest:
        shape = "closed " if closed else ""
        raise rd.fail(
            at,
            f"a {shape}{kind} target needs at least {fewest} points, got {len(rows)}",
        )
    bad = np.flatnonzero(~np.all(np.isfinite(rows.reshape(len(rows), -1)), axis=1))
    if len(bad):
        raise rd.fail(f"{at}[{bad[0]}]", "a value that is not finite")
    if kind == "motion":
        norms = np.linalg.norm(rows[:, 3:], axis=1)
        off = np.flatnonzero(np.abs(norms - 1.0) > UNIT_SLACK)
        if len(off):
            raise rd.fail(
                f"{at}[{off[0]}]",
                f"the quaternion (qw, qx, qy, qz) has norm {norms[off[0]]:.6g}, not 1",
            )
    if kind != "function":
        _distinct(rd, at, rows, closed)


def _distinct(rd: Reader, at: str, rows: np.ndarray, closed: bool) -> None:
    """No two rows are the same point (a closed curve's last row repeating its first
    included)."""
    spread = max(float(np.ptp(rows[:, :3], axis=0).max()), 1e-300)
    gaps = np.linalg.norm(rows[:, None, :] - rows[None, :, :], axis=2)
    gaps[np.tril_indices(len(rows))] = np.inf
    i, j = np.unravel_index(int(np.argmin(gaps)), gaps.shape)
    if gaps[i, j] <= DUPLICATE * spread:
        hint = (
            " (a closed curve's last point repeats its first; leave it out)"
            if closed and (i, j) == (0, len(rows) - 1)
            else ""
        )
        raise rd.fail(f"{at}[{j}]", f"duplicates point {i}{hint}")
