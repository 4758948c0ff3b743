"""Task points of a DH synthesis read from a CSV/text file (``linkopt arm
manipulability POINTS``).

Limits (checked before the synthesis): at most :data:`MAX_POINTS` points, each
coordinate at most :data:`~linkopt._arms.limits.MAX_MAGNITUDE` in magnitude (the cost
squares distances), files at most 16 MiB (checked before reading).
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..._errors import InputError
from .. import limits

#: The synthesis has one joint vector per point among its unknowns.
MAX_POINTS = 10_000

_SPLIT = re.compile(r"[,;\s]+")


def read_points(path: str | Path) -> np.ndarray:
    """Task points ``(m, 3)`` from a CSV/text file: one ``x, y, z`` per line (comma,
    semicolon or whitespace separated), ``#`` comments, an optional header line."""
    path = Path(path)
    rows, header_allowed = [], True
    for number, line in enumerate(_lines(path), start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        cells = [c for c in _SPLIT.split(text) if c]
        values = _numbers(cells)
        if values is None and header_allowed:
            header_allowed = False
            continue
        if values is None or len(values) != 3 or not np.all(np.isfinite(values)):
            raise InputError(
                f"{path}: line {number}: expected 3 finite numbers (x, y, z), "
                f"got {text!r}"
            )
        _check_row(path, number, values, len(rows))
        rows.append(values)
        header_allowed = False
    if not rows:
        raise InputError(f"{path}: no task points (expected lines of x, y, z)")
    return np.array(rows)


def _check_row(path: Path, number: int, values: list[float], count: int) -> None:
    if max(abs(v) for v in values) > limits.MAX_MAGNITUDE:
        raise InputError(
            f"{path}: line {number}: expected coordinates of magnitude at most "
            f"{limits.MAX_MAGNITUDE:g}, got {values}"
        )
    if count >= MAX_POINTS:
        raise InputError(
            f"{path}: line {number}: more than {MAX_POINTS} task points (the limit)"
        )


def _lines(path: Path) -> list[str]:
    limits.file_size(path, lambda m: InputError(f"{path}: {m}"), "task-point file")
    try:
        return path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as err:
        reason = getattr(err, "strerror", None) or err
        raise InputError(
            f"{path}: cannot read the task-point file ({reason})"
        ) from None


def _numbers(cells: list[str]) -> list[float] | None:
    try:
        return [float(c) for c in cells]
    except ValueError:
        return None
