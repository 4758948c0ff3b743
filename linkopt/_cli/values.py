"""Values given on the command line: ``v1,v2,...`` rows, CSV files of rows, and
``--design``.

Each reader raises :class:`~linkopt.InputError` with one line naming the option or the
file (and row) and what was expected.
"""

from __future__ import annotations

import csv
from pathlib import Path

import numpy as np

from .._engine.loader import load
from .._errors import InputError


def parse_row(text: str, names: tuple[str, ...], where: str) -> list[float]:
    """One row of ``len(names)`` comma-separated finite numbers."""
    expected, what = len(names), ", ".join(names)
    cells = [c.strip() for c in text.split(",") if c.strip() != ""]
    try:
        values = [float(c) for c in cells]
    except ValueError:
        raise InputError(
            f"{where}: expected {expected} comma-separated numbers ({what}), "
            f"got {text!r}"
        ) from None
    if len(values) != expected or not np.all(np.isfinite(values)):
        raise InputError(
            f"{where}: expected {expected} finite numbers ({what}), "
            f"got {len(values)}: {text!r}"
        )
    return values


def read_values(arg: str, names: tuple[str, ...], what: str) -> tuple[np.ndarray, bool]:
    """Values from ``v1,v2,...`` or a CSV file of rows (optional header); returns
    (values, is_path)."""
    path = Path(arg)
    if not (arg.lower().endswith(".csv") or path.is_file()):
        return np.array(parse_row(arg, names, f"--{what}")), False
    rows = _csv_rows(arg, path)
    if rows and rows[0] and not _is_number(rows[0][0]):
        header = [c.strip() for c in rows[0]]
        if header != list(names):
            raise InputError(
                f"{arg}: line 1: header {header} does not match the {what} "
                f"{list(names)}"
            )
        rows = rows[1:]
    if not rows:
        raise InputError(f"{arg}: no data rows")
    values = [
        parse_row(",".join(r), names, f"{arg}: row {k + 1}") for k, r in enumerate(rows)
    ]
    return np.array(values), True


def _csv_rows(arg: str, path: Path) -> list[list[str]]:
    """The non-blank rows of a CSV file."""
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as err:
        raise InputError(f"{arg}: cannot read CSV file ({err.strerror})") from None
    except UnicodeDecodeError as err:
        raise InputError(
            f"{arg}: not a UTF-8 text file (byte {err.start}); expected a CSV file of "
            "numbers"
        ) from None
    return [r for r in csv.reader(lines) if any(c.strip() for c in r)]


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def design_arg(mech, text: str | None) -> np.ndarray | None:
    """``--design``: comma-separated values in parameter order, or a mechanism file
    whose parameters (same names) hold the design."""
    if text is None:
        return None
    names = mech.design.names
    if text.lower().endswith(".toml"):
        other = load(text)
        if other.design.names != names:
            raise InputError(
                f"{text}: parameters {list(other.design.names)} do not match those "
                f"of {mech.source}: {list(names)}"
            )
        return other.design.p0
    values = np.array(parse_row(text, names, "--design"))
    outside = (values < mech.design.lower) | (values > mech.design.upper)
    if np.any(outside):
        k = int(np.argmax(outside))
        raise InputError(
            f"--design: {names[k]} = {values[k]:g} is outside its bounds "
            f"[{mech.design.lower[k]:g}, {mech.design.upper[k]:g}]"
        )
    return values
