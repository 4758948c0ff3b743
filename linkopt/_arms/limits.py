"""Bounds on the serial-arm input files, and bounded field reading.

Every arm input (arm task files, trace task files, task-point files) is checked against
these limits before any work, so that a meaningless or absurd value is one error line
naming the file and field instead of a wrong answer, a traceback or hours of work. The
limits assume a modest machine (2 cores, 24 GiB); each message states the value, the
limit and what to change.

* :data:`MAX_FILE_BYTES`: input files are text a person writes; a larger one is refused
  before it is read.
* :data:`MAX_MAGNITUDE`: the largest absolute value of any number (coordinates, masses,
  torques, weights ...); beyond it, squares and sums of squares lose every digit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from jaxtyping import Float

from .._files.fields import Reader, is_finite_number, is_number_list

MAX_FILE_BYTES = 16 * 2**20
MAX_MAGNITUDE = 1e6


def file_size(path: Path, fail, what: str = "file") -> None:
    """Refuse a file larger than :data:`MAX_FILE_BYTES` before reading it; ``fail``
    makes the error from a message. A missing file is left to the reader."""
    try:
        size = path.stat().st_size
    except OSError:
        return
    if size > MAX_FILE_BYTES:
        raise fail(
            f"{what} of {size / 2**20:.1f} MiB exceeds the limit of "
            f"{MAX_FILE_BYTES / 2**20:.0f} MiB"
        )


def number(
    rd: Reader,
    data: dict,
    key: str,
    where: str,
    limit: float = MAX_MAGNITUDE,
    unit: str = "",
) -> float:
    """A finite number of magnitude at most ``limit``."""
    value = rd.number(data, key, where)
    if abs(value) > limit:
        raise rd.fail(
            f"{where}.{key}",
            f"expected a magnitude of at most {limit:g}{unit}, got {data[key]!r}",
        )
    return value


def positive(
    rd: Reader,
    data: dict,
    key: str,
    where: str,
    limit: float = MAX_MAGNITUDE,
    as_written: bool = False,
) -> float:
    """A number in ``(0, limit]``."""
    value = rd.positive(data, key, where, as_written)
    if value > limit:
        raise rd.fail(
            f"{where}.{key}",
            f"expected a positive number of at most {limit:g}, got {data[key]!r}",
        )
    return value


def non_negative(
    rd: Reader, data: dict, key: str, where: str, what: str = "number"
) -> float:
    """A number in ``[0, MAX_MAGNITUDE]`` (a mass, a payload ...)."""
    value = number(rd, data, key, where)
    if value < 0:
        raise rd.fail(f"{where}.{key}", f"expected a {what} >= 0, got {data[key]!r}")
    return value


def _entries_ok(value, size: int, limit: float) -> bool:
    return (
        isinstance(value, list)
        and len(value) == size
        and all(is_finite_number(v) and abs(v) <= limit for v in value)
    )


def vector(
    rd: Reader, data: dict, key: str, where: str, limit: float = MAX_MAGNITUDE
) -> Float[np.ndarray, " 3"]:
    """A list of 3 finite numbers of magnitude at most ``limit``."""
    return _bounded(rd, rd.vector(data, key, where), 3, data, key, where, limit)


def point(
    rd: Reader, data: dict, key: str, where: str, limit: float = MAX_MAGNITUDE
) -> Float[np.ndarray, " 2"]:
    """A planar point ``[x, y]`` of magnitude at most ``limit``."""
    return _bounded(rd, rd.point(data, key, where), 2, data, key, where, limit)


def _bounded(rd: Reader, value, size, data, key, where, limit) -> np.ndarray:
    """``value`` (read from ``data[key]`` as ``size`` coordinates), refused when an
    entry's magnitude exceeds ``limit``."""
    if not _entries_ok(data[key], size, limit):
        raise rd.fail(
            f"{where}.{key}",
            f"expected coordinates of magnitude at most {limit:g}, got {data[key]!r}",
        )
    return value


def direction(rd: Reader, data: dict, key: str, where: str) -> Float[np.ndarray, " 3"]:
    """A non-zero direction of bounded entries (their norm cannot overflow)."""
    vector(rd, data, key, where)
    return rd.direction(data, key, where)


def count_limit(rd: Reader, where: str, count: int, limit: int, what: str) -> None:
    """At most ``limit`` entries of ``what``."""
    if count > limit:
        raise rd.fail(where, f"{count} {what} exceed the limit of {limit}")


def orientation(rd: Reader, value, where: str) -> Float[np.ndarray, "3 3"]:
    """A rotation matrix given as its three rows."""
    ok = (
        isinstance(value, list)
        and len(value) == 3
        and all(is_number_list(r, 3) for r in value)
    )
    matrix = np.asarray(value, dtype=float) if ok else None
    if (
        matrix is None
        or np.abs(matrix @ matrix.T - np.eye(3)).max() > 1e-6
        or np.linalg.det(matrix) < 0
    ):
        raise rd.fail(
            where, "expected a 3x3 rotation matrix (rows, orthonormal, det +1)"
        )
    return matrix
