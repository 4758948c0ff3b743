"""The optimiser's checkpoint file (``DIR/checkpoint.json``): its contents, and their
validation on ``--resume``.

A checkpoint is whatever a user's disk holds: it may be truncated, replaced by another
file, edited, or of another linkopt run. :func:`decode` checks every field a resumed run
reads (types, shapes against the mechanism's parameters and the settings' particle
count, finite positions, an RNG state numpy accepts, one history record per finished
iteration) before the run is rebuilt, so a bad checkpoint is one
:class:`~linkopt.InputError` line naming the file and field, raised before any
optimisation work starts, rather than a traceback or a silently different run later.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .._engine.model import Mechanism, fingerprint
from .._errors import InputError
from .optimizer import OptimizerSettings, SwarmRun

CHECKPOINT = "checkpoint.json"
HISTORY_FIELDS = [
    "iteration",
    "best_total",
    "best_f_design",
    "regularizer",
    "reach",
    "singularity",
    "evaluations",
    "wall_time",
]
#: The run's array fields, stored in the checkpoint as nested lists.
ARRAYS = ("position", "velocity", "pbest_pos", "pbest_cost", "best_pos")
_REQUIRED = (
    "mechanism",
    "settings",
    "iteration",
    "best_cost",
    "rng_state",
    "history",
    "stalled",
    "finished",
    "limit",
    "rounds",
    *ARRAYS,
)
_WRITTEN_BY = "a checkpoint written by linkopt optimize"
_ROUND_KEYS = (
    "round",
    "iteration",
    "design",
    "passed",
    "coverage",
    "max_f_sing",
    "threshold",
    "added_targets",
    "verification",
)


def encode(run: SwarmRun, mech: Mechanism, settings: OptimizerSettings) -> dict:
    """The checkpoint's contents (JSON-ready; infinities as ``Infinity``)."""
    arrays = {k: getattr(run, k).tolist() for k in ARRAYS}
    return {
        "mechanism": fingerprint(mech),
        "settings": settings.to_dict(),
        "iteration": run.iteration,
        "best_cost": run.best_cost,
        "rng_state": run.rng_state,
        "history": list(run.history),
        "stalled": run.stalled,
        "finished": run.finished,
        "result_pos": None if run.result_pos is None else run.result_pos.tolist(),
        "result_total": run.result_total,
        "result_feasible": run.result_feasible,
        "limit": run.limit,
        "rounds": list(run.rounds),
        **arrays,
    }


def read(out: Path) -> dict:
    """The parsed checkpoint of the run folder ``out``: a JSON object; InputError when
    there is none or it is not one."""
    path = out / CHECKPOINT
    try:
        text = path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise InputError(
            f"{out}: no checkpoint to resume ({CHECKPOINT} missing)"
        ) from None
    except IsADirectoryError:
        raise InputError(f"{path}: expected {_WRITTEN_BY}, found a directory") from None
    except OSError as err:
        raise InputError(
            f"{path}: cannot read the checkpoint ({err.strerror or err})"
        ) from None
    except UnicodeDecodeError:
        raise InputError(
            f"{path}: unreadable checkpoint (not UTF-8 text); expected {_WRITTEN_BY}"
        ) from None
    try:
        data = json.loads(text)
    except (ValueError, RecursionError) as err:
        reason = " ".join(str(err).split()) or type(err).__name__
        raise InputError(
            f"{path}: unreadable checkpoint ({reason}); expected {_WRITTEN_BY}"
        ) from None
    if not isinstance(data, dict):
        raise InputError(
            f"{path}: expected {_WRITTEN_BY} (a JSON object), got {_kind(data)}"
        )
    missing = [k for k in _REQUIRED if k not in data]
    if missing:
        raise InputError(
            f"{path}: missing field{'s' if len(missing) > 1 else ''} "
            f"{', '.join(missing)}; expected {_WRITTEN_BY}"
        )
    return data


def check_match(
    path: Path, data: dict, mech: Mechanism, settings: OptimizerSettings
) -> None:
    """Refuse a checkpoint of another mechanism or made with other settings."""
    if not isinstance(data["mechanism"], str):
        raise _bad(path, "mechanism", "a fingerprint string", data["mechanism"])
    if not isinstance(data["settings"], dict):
        raise _bad(path, "settings", "a table of optimiser settings", data["settings"])
    if data["mechanism"] != fingerprint(mech):
        raise InputError(
            f"{path}: the checkpoint belongs to a different mechanism file; "
            "use another --out"
        )
    if data["settings"] != settings.to_dict():
        now = settings.to_dict()
        changed = sorted(
            k
            for k in set(data["settings"]) | set(now)
            if data["settings"].get(k) != now.get(k)
        )
        raise InputError(
            f"{path}: the checkpoint was made with other settings "
            f"({', '.join(changed)}); resume with the same flags"
        )


def decode(
    path: Path, data: dict, mech: Mechanism, settings: OptimizerSettings
) -> SwarmRun:
    """The run stored in ``data`` (from :func:`read`, of ``mech`` with ``settings``:
    :func:`check_match`), every field checked (module docstring)."""
    n, size = settings.particles, mech.design.size
    shapes = {
        "position": (n, size),
        "velocity": (n, size),
        "pbest_pos": (n, size),
        "pbest_cost": (n,),
        "best_pos": (size,),
    }
    arrays = {
        k: _array(path, k, data[k], shape, infinite=k == "pbest_cost")
        for k, shape in shapes.items()
    }
    iteration = _count(path, data, "iteration")
    finished = _flag(path, "finished", data["finished"])
    result = _result(path, data, size, required=finished)
    if finished and iteration == 0:
        raise _bad(path, "iteration", "at least 1 in a finished run", iteration)
    history = _history(path, data["history"], iteration)
    limit = _count(path, data, "limit")
    least = max(settings.iterations, iteration + (not finished))
    if limit < least:
        raise _bad(path, "limit", f"an iteration count of at least {least}", limit)
    return SwarmRun(
        **arrays,
        iteration=iteration,
        best_cost=_number(path, "best_cost", data["best_cost"]),
        rng_state=_rng_state(path, data["rng_state"]),
        history=history,
        stalled=_count(path, data, "stalled"),
        finished=finished,
        **result,
        limit=limit,
        rounds=_rounds(path, data["rounds"], iteration, size, mech.num_outputs),
    )


def _rounds(path: Path, rounds, iteration: int, size: int, outputs: int) -> tuple:
    """The verification rounds (:mod:`linkopt._design.rounds`): numbered in order, each
    at a finished iteration, with its design, outcome and added targets."""
    if not isinstance(rounds, list):
        raise _bad(path, "rounds", "a list of verification rounds", rounds)
    last = 0
    for k, record in enumerate(rounds):
        where = f"rounds[{k}]"
        if not isinstance(record, dict):
            raise _bad(path, where, "an object", record)
        missing = [key for key in _ROUND_KEYS if key not in record]
        if missing:
            raise _bad(path, where, f"the fields {', '.join(_ROUND_KEYS)}", record)
        if record["round"] != k or isinstance(record["round"], bool):
            raise _bad(path, f"{where}.round", str(k), record["round"])
        step = record["iteration"]
        if not _is_integer(step) or not last < step <= iteration:
            raise _bad(path, f"{where}.iteration", f"in {last + 1}..{iteration}", step)
        last = step
        _flag(path, f"{where}.passed", record["passed"])
        _array(path, f"{where}.design", record["design"], (size,))
        for key in ("coverage", "max_f_sing", "threshold"):
            _number(path, f"{where}.{key}", record[key])
        added = record["added_targets"]
        if not isinstance(added, list):
            raise _bad(path, f"{where}.added_targets", "a list of targets", added)
        if added:
            _array(path, f"{where}.added_targets", added, (len(added), outputs))
        if not isinstance(record["verification"], dict):
            raise _bad(path, f"{where}.verification", "an object", record)
    return tuple(rounds)


def _result(path: Path, data: dict, size: int, required: bool) -> dict:
    """The returned design's fields; checkpoints written before they existed have
    none, which is only acceptable while the run has more iterations to go."""
    position = data.get("result_pos")
    if position is None and required:
        raise _bad(path, "result_pos", f"{size} design values in a finished run", None)
    return {
        "result_pos": None
        if position is None
        else _array(path, "result_pos", position, (size,)),
        "result_total": _number(
            path, "result_total", data.get("result_total", float("inf"))
        ),
        "result_feasible": _flag(
            path, "result_feasible", data.get("result_feasible", False)
        ),
    }


def _kind(value) -> str:
    """A short description of a JSON value for an error message."""
    if isinstance(value, list):
        return f"a list of {len(value)}"
    if isinstance(value, dict):
        return "an object"
    text = repr(value)
    return text if len(text) <= 40 else text[:37] + "..."


def _bad(path: Path, field: str, expected: str, got) -> InputError:
    return InputError(f"{path}: {field}: expected {expected}, got {_kind(got)}")


def _is_integer(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _count(path: Path, data: dict, key: str) -> int:
    if not _is_integer(data[key]) or data[key] < 0:
        raise _bad(path, key, "a non-negative integer", data[key])
    return data[key]


def _flag(path: Path, field: str, value) -> bool:
    if not isinstance(value, bool):
        raise _bad(path, field, "true or false", value)
    return value


def _number(path: Path, field: str, value) -> float:
    """A number, possibly infinite (a cost not yet finite), never NaN."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not ok or math.isnan(value):
        raise _bad(path, field, "a number", value)
    return float(value)


def _array(
    path: Path, field: str, value, shape: tuple, infinite: bool = False
) -> np.ndarray:
    """Nested lists of numbers of ``shape``, finite (or ``+inf`` where ``infinite``:
    costs not yet evaluated)."""
    what = "x".join(map(str, shape))
    expected = f"a {what} array of finite numbers"
    try:
        array = np.array(value)
    except (ValueError, TypeError):  # ragged
        raise _bad(path, field, expected, value) from None
    if array.dtype.kind not in "iuf" or array.shape != shape:
        got = f"shape {array.shape}" if array.dtype.kind in "iuf" else _kind(value)
        raise InputError(f"{path}: {field}: expected {expected}, got {got}")
    array = array.astype(float)
    bad = ~np.isfinite(array) & ~(infinite & (array == np.inf))
    if bad.any():
        raise InputError(
            f"{path}: {field}: expected {expected}, got {array[bad][0]} at index "
            f"{tuple(int(i) for i in np.argwhere(bad)[0])}"
        )
    return array


def _rng_state(path: Path, state) -> dict:
    """A PCG64 state (``numpy.random.Generator.bit_generator.state``) numpy accepts."""
    expected = "a PCG64 generator state written by numpy"
    inner = state.get("state") if isinstance(state, dict) else None
    ok = (
        isinstance(state, dict)
        and state.get("bit_generator") == "PCG64"
        and isinstance(inner, dict)
        and all(
            _is_integer(inner.get(k)) and 0 <= inner[k] < 2**128
            for k in ("state", "inc")
        )
        and state.get("has_uint32") in (0, 1)
        and _is_integer(state.get("uinteger"))
        and 0 <= state["uinteger"] < 2**32
    )
    if ok:
        try:
            np.random.default_rng().bit_generator.state = state
        except (TypeError, ValueError, KeyError, OverflowError):
            ok = False
    if not ok:
        raise _bad(path, "rng_state", expected, state)
    return state


def _history(path: Path, history, iteration: int) -> tuple:
    """One record per finished iteration, each with the numbers ``history.csv`` and
    the convergence plot read (NaN allowed: a swarm of failed evaluations)."""
    if not isinstance(history, list) or len(history) != iteration:
        raise _bad(path, "history", f"a list of {iteration} records", history)
    for k, record in enumerate(history):
        if not isinstance(record, dict):
            raise _bad(path, f"history[{k}]", "an object", record)
        for key in HISTORY_FIELDS:
            value = record.get(key)
            if not isinstance(value, (int, float)) or isinstance(value, bool):
                raise _bad(path, f"history[{k}].{key}", "a number", value)
    return tuple(history)
