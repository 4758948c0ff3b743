"""Task points of a DH synthesis read from a CSV/text file (``linkopt arm
manipulability POINTS``)."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from ..._errors import InputError

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
        rows.append(values)
        header_allowed = False
    if not rows:
        raise InputError(f"{path}: no task points (expected lines of x, y, z)")
    return np.array(rows)


def _lines(path: Path) -> list[str]:
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
