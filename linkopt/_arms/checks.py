"""Argument checks shared by the serial-arm commands and their library entry points.

Each raises :class:`~linkopt.InputError` with one line naming the argument (``where``)
and what was expected.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .._errors import InputError


def seed(value, where: str = "seed") -> int:
    """A seed of ``np.random.default_rng``: a non-negative integer."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
        raise InputError(f"{where}: expected a non-negative integer, got {value!r}")
    return int(value)


def count(value, where: str, minimum: int = 1, maximum: int | None = None) -> int:
    """An integer of at least ``minimum`` (starts, workers, restarts ...) and, given
    ``maximum``, at most that (a limit on the work it asks for)."""
    if (
        isinstance(value, bool)
        or not isinstance(value, (int, np.integer))
        or value < minimum
    ):
        what = "a positive integer" if minimum == 1 else f"an integer >= {minimum}"
        raise InputError(f"{where}: expected {what}, got {value!r}")
    if maximum is not None and value > maximum:
        raise InputError(f"{where}: {value} exceeds the limit of {maximum}")
    return int(value)


def number(
    value, where: str, *, positive: bool = False, maximum: float = 1e12
) -> float:
    """A finite number ``>= 0`` (``> 0`` when ``positive``) of at most ``maximum``."""
    ok = (
        not isinstance(value, bool)
        and isinstance(value, (int, float, np.integer, np.floating))
        and bool(np.isfinite(value))
        and (value > 0 if positive else value >= 0)
    )
    if not ok:
        what = "positive" if positive else "non-negative"
        raise InputError(f"{where}: expected a finite {what} number, got {value!r}")
    if value > maximum:
        raise InputError(f"{where}: {value!r} exceeds the limit of {maximum:g}")
    return float(value)


def output_directory(text: str, where: str = "--out") -> Path:
    """An output directory, created if needed; :class:`InputError` when it cannot be
    (an existing file of that name, no permission ...)."""
    out = Path(text)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(
            f"{where}: cannot create the output directory {text!r} "
            f"({err.strerror or err})"
        ) from None
    return out
