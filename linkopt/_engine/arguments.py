"""Argument checks of the public solves (:mod:`.kinematics`): shapes always (also of
traced arrays), finite values and ranges of concrete arrays. Each raises
:class:`~linkopt.InputError` naming the argument."""

from __future__ import annotations

import jax
import numpy as np

from .. import _config  # noqa: F401  (float64 on before any array)
from .._errors import InputError
from .model import Mechanism

#: Largest magnitude of a motor value or output the public solves accept (homogenised:
#: rad, or reference lengths). A continuation moves at most ``MAX_STEPS · MAX_STEP`` =
#: 80 from its start, so larger values are never reached, and near 1e308 the step
#: arithmetic overflows to NaN.
MAX_VALUE = 1e6


def value_scale(mech: Mechanism, kind: str):
    """The homogenising scale of motor values (``kind`` "fk") or outputs ("bk")."""
    return mech.motor_scale if kind == "fk" else mech.output_scale


def _numbers(name: str, value):
    """``value`` as a float64 array, or None when it is traced (shape checks only)."""
    if isinstance(value, jax.core.Tracer):
        return None
    try:
        return np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(
            f"{name}: expected an array of numbers, got {type(value).__name__}"
        ) from None


def _shape(name: str, value, array) -> tuple[int, ...]:
    return tuple(value.shape) if array is None else array.shape


def _finite(name: str, array) -> None:
    if array is not None and not np.all(np.isfinite(array)):
        raise InputError(f"{name}: expected finite numbers, got NaN or infinity")


def check_design(mech: Mechanism, design, name: str = "design") -> None:
    """``design`` is None or ``(P,)`` finite numbers, P the file's parameter count."""
    if design is None:
        return
    array = _numbers(name, design)
    shape = _shape(name, design, array)
    if shape != (mech.design.size,):
        raise InputError(
            f"{name}: expected shape ({mech.design.size},) "
            f"({', '.join(mech.design.names)}), got {shape}"
        )
    _finite(name, array)


def check_state(mech: Mechanism, state, name: str = "state", batch=False) -> None:
    """``state`` is a finite homogenised state ``(S,)``; with ``batch`` True also a
    stack ``(N, S)``, N ≥ 1, and with an int ``batch`` a stack of that many."""
    array = _numbers(name, state)
    shape, size = _shape(name, state, array), mech.state_size
    stacked = len(shape) == 2 and shape[1] == size and shape[0] >= 1
    if batch is True:
        ok, allowed = stacked, f"({size},) or (N, {size})"
    elif batch is False:
        ok, allowed = False, f"({size},)"
    else:
        ok, allowed = stacked and shape[0] == batch, f"({size},) or ({batch}, {size})"
    if not (shape == (size,) or ok):
        raise InputError(f"{name}: expected a homogenised state {allowed}, got {shape}")
    _finite(name, array)


def check_values(mech: Mechanism, kind: str, values, *, path: bool = False) -> int:
    """Motor values (``kind`` "fk") or outputs ("bk"), file units: ``(W,)`` or
    ``(N, W)`` (a path: ``(T, W)``), N, T ≥ 1, finite and within ``MAX_VALUE``
    homogenised units. Returns the batch size N, None for one row ``(W,)``."""
    name = "motors" if kind == "fk" else "outputs"
    names = mech.motor_names if kind == "fk" else mech.output_names
    array = _numbers(name, values)
    shape, width = _shape(name, values, array), len(names)
    if path:
        ok, expected = len(shape) == 2, f"(T, {width}) with T >= 1"
    else:
        ok, expected = len(shape) in (1, 2), f"({width},) or (N, {width}) with N >= 1"
    if not ok or shape[-1] != width or (len(shape) == 2 and shape[0] == 0):
        raise InputError(
            f"{name}: expected shape {expected} ({', '.join(names)}), got {shape}"
        )
    _finite(name, array)
    if array is not None:
        _check_range(name, names, array.reshape(-1, width), value_scale(mech, kind))
    return None if len(shape) == 1 else shape[0]


def _check_range(name: str, names, rows, scale) -> None:
    bound = MAX_VALUE * np.asarray(scale)
    outside = np.any(np.abs(rows) > bound, axis=0)
    if np.any(outside):
        k = int(np.argmax(outside))
        raise InputError(
            f"{name}: {names[k]} = {float(np.max(np.abs(rows[:, k]))):g} is out of "
            f"range: expected |{names[k]}| <= {float(bound[k]):g}"
        )


def check_arguments(
    mech: Mechanism, kind: str, values, start, design, path: bool
) -> None:
    """Every argument of a public solve of :mod:`.kinematics`."""
    rows = check_values(mech, kind, values, path=path)
    if start is not None:
        check_state(mech, start, "start", batch=False if path or not rows else rows)
    check_design(mech, design)
