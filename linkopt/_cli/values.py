"""Values given on the command line: the mechanism file (:func:`load`), ``v1,v2,...``
rows, CSV files of rows, and ``--design``.

Each reader raises :class:`~linkopt.InputError` with one line naming the option or the
file (and row) and what was expected. Values are finite and, where ``bounds`` are
given, within ``±bounds`` (the solvers' range, :data:`linkopt._engine.kinematics.
MAX_VALUE` homogenised units); a CSV file holds at most ``max_rows`` data rows and
``MAX_CSV_BYTES`` bytes, checked before it is parsed.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .._errors import InputError
from .._files.fields import parse_text

#: Largest CSV file read (bytes): a path of :data:`MAX_ROWS` rows of a few numbers each
#: is well under it, and a larger file is refused before it is read into memory.
MAX_CSV_BYTES = 64 * 2**20
#: Default cap on a CSV path's data rows (``--max-rows``): each row is a continuation
#: solve and a record of every joint and point, read off by a few calls of some
#: milliseconds each, so 10 000 rows is about a minute.
MAX_ROWS = 10_000


def parse_row(
    text: str, names: tuple[str, ...], where: str, bounds=None
) -> list[float]:
    """One row of ``len(names)`` comma-separated finite numbers, each within
    ``±bounds`` when given."""
    expected, what = len(names), ", ".join(names)
    cells = [c.strip() for c in text.split(",") if c.strip() != ""]
    try:
        values = [float(c) for c in cells]
    except ValueError:
        raise InputError(
            f"{where}: expected {expected} comma-separated numbers ({what}), "
            f"got {_shown(text)}"
        ) from None
    if len(values) != expected or not np.all(np.isfinite(values)):
        raise InputError(
            f"{where}: expected {expected} finite numbers ({what}), "
            f"got {len(values)}: {_shown(text)}"
        )
    if bounds is not None:
        _check_bounds(values, names, where, bounds)
    return values


def _shown(text: str, limit: int = 80) -> str:
    """``text`` quoted, cut to ``limit`` characters (a line of the message)."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + "..."


def _check_bounds(values: list[float], names, where: str, bounds) -> None:
    outside = np.abs(values) > np.asarray(bounds)
    if np.any(outside):
        k = int(np.argmax(outside))
        raise InputError(
            f"{where}: {names[k]} = {values[k]:g} is out of range: expected "
            f"|{names[k]}| <= {float(np.asarray(bounds)[k]):g}"
        )


def read_values(
    arg: str,
    names: tuple[str, ...],
    what: str,
    bounds=None,
    max_rows: int = MAX_ROWS,
) -> tuple[np.ndarray, bool]:
    """Values from ``v1,v2,...`` or a CSV file of rows; returns (values, is_path).

    A CSV header (optional) names the columns: every one of ``names`` once, in any
    order; the values come back in ``names`` order."""
    path = Path(arg)
    if not (arg.lower().endswith(".csv") or _is_file(path)):
        return np.array(parse_row(arg, names, f"--{what}", bounds)), False
    rows = _csv_rows(arg, path)
    order = list(range(len(names)))
    if rows and rows[0] and not _is_number(rows[0][0]):
        order = _header_order([c.strip() for c in rows[0]], names, arg, what)
        rows = rows[1:]
    if not rows:
        raise InputError(f"{arg}: no data rows")
    if len(rows) > max_rows:
        raise InputError(
            f"{arg}: {len(rows)} data rows, more than the limit of {max_rows} "
            "(raise it with --max-rows)"
        )
    columns = tuple(names[k] for k in order)
    column_bounds = None if bounds is None else np.asarray(bounds)[order]
    values = np.array(
        [
            parse_row(",".join(r), columns, f"{arg}: row {k + 1}", column_bounds)
            for k, r in enumerate(rows)
        ]
    )
    return values[:, np.argsort(order)], True


def _header_order(
    header: list[str], names: tuple[str, ...], arg: str, what: str
) -> list[int]:
    """The index in ``names`` of each header column: every name once, in any
    order."""
    unknown = [h for h in header if h not in names]
    if unknown:
        raise InputError(
            f"{arg}: line 1: header column {_shown(unknown[0])} is not one of the "
            f"{what} {list(names)} (any order)"
        )
    repeated = [h for h in header if header.count(h) > 1]
    if repeated:
        raise InputError(
            f"{arg}: line 1: header column {_shown(repeated[0])} appears twice"
        )
    missing = [n for n in names if n not in header]
    if missing:
        raise InputError(
            f"{arg}: line 1: header lacks the {what} {missing}; expected "
            f"{list(names)} (any order)"
        )
    return [names.index(h) for h in header]


def _is_file(path: Path) -> bool:
    """``path.is_file()``, False where the name cannot be a file (too long)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


def _csv_rows(arg: str, path: Path) -> list[list[str]]:
    """The non-blank rows of a CSV file."""
    try:
        size = path.stat().st_size
        if size > MAX_CSV_BYTES:
            raise InputError(
                f"{arg}: {size / 2**20:.0f} MiB, larger than the limit of "
                f"{MAX_CSV_BYTES // 2**20} MiB for a CSV file of values"
            )
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as err:
        raise InputError(f"{arg}: cannot read CSV file ({err.strerror})") from None
    except UnicodeDecodeError as err:
        raise InputError(
            f"{arg}: not a UTF-8 text file (byte {err.start}); expected a CSV file of "
            "numbers"
        ) from None
    try:
        return [r for r in csv.reader(lines) if any(c.strip() for c in r)]
    except csv.Error as err:
        raise InputError(f"{arg}: not a CSV file of numbers ({err})") from None


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def load(path):
    """The mechanism file at ``path``, as :func:`linkopt.load` reads it; a file that
    cannot be read or is not TOML is refused before the engine (and JAX) is
    imported."""
    path = Path(path)
    data = parse_text(path)
    from .._files.loader import build

    return build(data, str(path))


def design_arg(mech, text: str | None) -> np.ndarray | None:
    """``--design``: comma-separated values in parameter order, or a mechanism file
    whose parameters (same names) hold the design; either within the parameters'
    bounds."""
    if text is None:
        return None
    names = mech.design.names
    if text.lower().endswith(".toml"):
        if not _is_file(Path(text)):
            raise InputError(f"--design: {text}: no such mechanism file")
        other = load(text)
        if other.design.names != names:
            raise InputError(
                f"{text}: parameters {list(other.design.names)} do not match those "
                f"of {mech.source}: {list(names)}"
            )
        return _same_mobility(mech, _within_bounds(mech, other.design.p0, text), text)
    values = np.array(parse_row(text, names, "--design"))
    return _same_mobility(mech, _within_bounds(mech, values, "--design"), "--design")


def _same_mobility(mech, values: np.ndarray, where: str) -> np.ndarray:
    """``values``, refused where the design changes the mobility at rest (the motors
    that no longer move named)."""
    from .._engine.mobility import check_design_mobility

    check_design_mobility(mech, values, where)
    return values


def _within_bounds(mech, values: np.ndarray, where: str) -> np.ndarray:
    names = mech.design.names
    outside = (values < mech.design.lower) | (values > mech.design.upper)
    if np.any(outside):
        k = int(np.argmax(outside))
        raise InputError(
            f"{where}: {names[k]} = {values[k]:g} is outside its bounds "
            f"[{mech.design.lower[k]:g}, {mech.design.upper[k]:g}]"
        )
    return values


def at_design(mech, design: np.ndarray | None):
    """``mech`` with ``design`` as its file's design (None: ``mech``): the mechanism
    that the file written at ``design`` (``optimize``'s ``optimized.toml``) reads back
    as, with the file's own ``alpha_minus`` (or none) and checks, so ``check
    --design`` reports what ``check`` of that file would."""
    if design is None:
        return mech
    from .._files.loader import build
    from .._files.writer import design_definition

    data = design_definition(mech, design, 0.0)
    if mech.evaluation.alpha_minus is None:
        del data["evaluation"]["alpha_minus"]
    else:
        data["evaluation"]["alpha_minus"] = float(mech.evaluation.alpha_minus)
    return build(data, mech.source)
