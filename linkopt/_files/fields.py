"""Typed reading of TOML input files: the one field reader of every file format.

Mechanism files (``loader``), arm task files (``_arms.codesign.task``) and trace task
files (``_arms.trace.task``) are read through :class:`Reader`: each check raises one
:class:`MechanismFileError` naming the file, the table/field and what was expected, so
that every format words the same problem the same way. Nothing here knows a format's
tables; :func:`parse_text` and :func:`parse_toml` turn a file or its text into tables.
"""

from __future__ import annotations

import math
import re
import sys
import tomllib
from pathlib import Path

import numpy as np
from jaxtyping import Float

from .._errors import MechanismFileError


def parse_text(path: Path) -> dict:
    """The tables of the TOML file at ``path``; unreadable files are one error line."""
    source = str(path)
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise MechanismFileError(source, "", "file not found") from None
    except (OSError, UnicodeDecodeError) as err:
        raise MechanismFileError(source, "", f"cannot read file ({err})") from None
    return parse_toml(text, source)


def parse_toml(text: str, source: str) -> dict:
    """TOML text -> tables; malformed TOML is one :class:`MechanismFileError` line."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise MechanismFileError(source, "", f"invalid TOML: {err}") from None
    except RecursionError:  # tomllib recurses once per level of nested arrays/tables
        raise MechanismFileError(
            source, "", "invalid TOML: arrays or tables nested too deeply"
        ) from None


#: Longest ``repr`` of a value quoted in a message; longer ones are cut with "...".
SHOWN_CHARS = 60


def shown(value) -> str:
    """``repr(value)`` for a message: one line (``repr`` escapes newlines), cut to
    :data:`SHOWN_CHARS` characters."""
    text = repr(value)
    return text if len(text) <= SHOWN_CHARS else text[: SHOWN_CHARS - 3] + "..."


def field_name(key: str) -> str:
    """A key as a message names it: bare where TOML allows it bare, else quoted."""
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else repr(key)


def is_finite_number(value) -> bool:
    """An int or float (not a bool, which TOML keeps apart) that is finite; an int
    (TOML integers have no size limit) too large for a float is not."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return False
    if isinstance(value, int):
        return abs(value) <= sys.float_info.max
    return math.isfinite(value)


def is_number_list(value, size: int) -> bool:
    """A list of exactly ``size`` finite numbers."""
    return (
        isinstance(value, list)
        and len(value) == size
        and all(is_finite_number(v) for v in value)
    )


class Reader:
    """Typed field access that raises with the file and field path.

    ``where`` is the path of the table being read (``joints[2]``, ``[solver]``); a
    field's problem is reported at ``where.key``.
    """

    def __init__(self, source: str):
        self.source = source

    def fail(self, where: str, message: str) -> MechanismFileError:
        """The error to raise for a problem at ``where`` of this file."""
        return MechanismFileError(self.source, where, message)

    def top_level(self, data: dict, allowed: set[str]) -> None:
        """Every top-level table is one the format knows."""
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise self.fail(
                field_name(unknown[0]),
                f"unknown table; expected one of {sorted(allowed)}",
            )

    def keys(
        self, data: dict, where: str, allowed: set[str], required: set[str]
    ) -> dict:
        """``data`` (a table) has only ``allowed`` keys and every ``required`` one."""
        unknown = sorted(set(data) - allowed)
        if unknown:
            raise self.fail(
                f"{where}.{field_name(unknown[0])}",
                f"unknown field; expected one of {sorted(allowed)}",
            )
        missing = sorted(required - set(data))
        if missing:
            raise self.fail(f"{where}.{missing[0]}", "missing required field")
        return data

    def table(self, data, where: str, allowed: set[str], required: set[str]) -> dict:
        """As :meth:`keys`, for a value not yet known to be a table."""
        if not isinstance(data, dict):
            raise self.fail(where, f"expected a table, got {shown(data)}")
        return self.keys(data, where, allowed, required)

    def string(self, data: dict, key: str, where: str) -> str:
        value = data[key]
        if not isinstance(value, str) or not value:
            raise self.fail(
                f"{where}.{key}", f"expected a non-empty string, got {shown(value)}"
            )
        return value

    def boolean(self, data: dict, key: str, where: str) -> bool:
        value = data[key]
        if not isinstance(value, bool):
            raise self.fail(
                f"{where}.{key}", f"expected true or false, got {shown(value)}"
            )
        return value

    def number(self, data: dict, key: str, where: str) -> float:
        value = data[key]
        if not is_finite_number(value):
            raise self.fail(
                f"{where}.{key}", f"expected a finite number, got {shown(value)}"
            )
        return float(value)

    def positive(
        self, data: dict, key: str, where: str, as_written: bool = False
    ) -> float:
        """A finite number > 0. The message quotes the value as read, a float
        (``-1.0``), or with ``as_written`` as the file spells it (``-1``), the wording
        of trace task files."""
        value = self.number(data, key, where)
        if value <= 0:
            text = repr(data[key] if as_written else value)
            raise self.fail(f"{where}.{key}", f"expected a positive number, got {text}")
        return value

    def positive_integer(self, data: dict, key: str, where: str) -> int:
        value = data[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < 1:
            raise self.fail(
                f"{where}.{key}", f"expected a positive integer, got {shown(value)}"
            )
        return value

    def vector(self, data: dict, key: str, where: str) -> Float[np.ndarray, " 3"]:
        value = data[key]
        if not is_number_list(value, 3):
            raise self.fail(
                f"{where}.{key}",
                f"expected a list of 3 finite numbers, got {shown(value)}",
            )
        return np.asarray(value, dtype=float)

    def point(self, data: dict, key: str, where: str) -> Float[np.ndarray, " 2"]:
        """A planar point ``[x, y]``."""
        value = data[key]
        if not is_number_list(value, 2):
            raise self.fail(
                f"{where}.{key}",
                f"expected a list of 2 finite numbers [x, y], got {shown(value)}",
            )
        return np.asarray(value, dtype=float)

    def direction(self, data: dict, key: str, where: str) -> Float[np.ndarray, " 3"]:
        """A non-zero 3-vector, normalised. Components so large that the length would
        overflow (``[1e200, 1e200, 0]``) are scaled first; shorter than ``1e-12`` is
        zero."""
        vec = self.vector(data, key, where)
        largest = float(np.max(np.abs(vec)))
        if largest > 1e150:  # its sum of squares would overflow
            vec = vec / largest
        norm = np.linalg.norm(vec) if largest > 1e-150 else 0.0
        if norm < 1e-12:
            raise self.fail(
                f"{where}.{key}", "zero-length axis; expected a non-zero direction"
            )
        return vec / norm

    def bounded(
        self, data: dict, key: str, where: str, low: float, high: float
    ) -> float:
        """A finite number in ``[low, high]``: the range a setting can take before it
        stops meaning anything (each format states its bounds and why)."""
        value = self.number(data, key, where)
        if not low <= value <= high:
            raise self.fail(
                f"{where}.{key}",
                f"expected a number from {low:g} to {high:g}, got {shown(data[key])}",
            )
        return value

    def integer(self, data: dict, key: str, where: str, low: int, high: int) -> int:
        """An integer (not a bool, nor a float such as ``3.0``) in ``[low, high]``."""
        value = data[key]
        if isinstance(value, bool) or not isinstance(value, int):
            raise self.fail(
                f"{where}.{key}", f"expected an integer, got {shown(value)}"
            )
        if not low <= value <= high:
            raise self.fail(
                f"{where}.{key}",
                f"expected an integer from {low} to {high}, got {shown(value)}",
            )
        return value

    def entries(self, data: dict, key: str, required: bool) -> list[dict]:
        """The array of tables ``[[key]]``; ``required``: at least one entry."""
        if key not in data:
            if required:
                raise self.fail(f"[[{key}]]", "missing; at least one entry is required")
            return []
        value = data[key]
        if not isinstance(value, list) or not all(isinstance(v, dict) for v in value):
            raise self.fail(
                f"[[{key}]]",
                f"expected an array of tables ([[{key}]]), got {shown(value)}",
            )
        if required and not value:
            raise self.fail(f"[[{key}]]", "empty; at least one entry is required")
        return value

    def array(self, data: dict, key: str) -> list:
        """The array under ``key``, empty when absent; its entries are left to the
        caller to check (trace task files, which report this at the bare key)."""
        value = data.get(key, [])
        if not isinstance(value, list):
            raise self.fail(key, "expected an array of tables ([[" + key + "]])")
        return value

    def names(self, items: list[dict], table: str) -> dict[str, int]:
        """Name -> index of the entries of ``[[table]]``; names are required, unique."""
        index: dict[str, int] = {}
        for k, item in enumerate(items):
            where = f"{table}[{k}]"
            if "name" not in item:
                raise self.fail(f"{where}.name", "missing required field")
            name = self.string(item, "name", where)
            if name in index:
                raise self.fail(
                    f"{where}.name",
                    f"duplicated name {shown(name)} (also {table}[{index[name]}])",
                )
            index[name] = k
        return index

    def lookup(self, names: dict[str, int], value, where: str, kind: str) -> int:
        """The index of the ``kind`` named ``value``."""
        if not isinstance(value, str) or value not in names:
            raise self.fail(
                where,
                f"unknown {kind} {shown(value)}; expected one of {sorted(names)}",
            )
        return names[value]
