"""The checkpoint of a ``linkopt synthesize`` run (``RUN/checkpoint.json``) and its
validation on ``--resume``, as ``linkopt optimize`` keeps its own
(:mod:`linkopt._design.checkpoint`).

After every iteration's move the whole swarm state (positions, velocities, personal
and global bests, the returned design, the RNG state, the history) is written
atomically, with the mechanism's fingerprint, the swarm settings, the cycle's rows
and the targets. ``--resume`` continues it exactly (every step is deterministic:
the resumed run ends where an uninterrupted one with the same seed does); a
checkpoint of another mechanism, other settings or targets, or one whose fields are
not what a run writes, is refused with one line naming the file and the field,
before any work.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import math
from pathlib import Path

import numpy as np

from .._design.optimizer import SwarmRun
from .._design.settings import OptimizerSettings
from .._engine.model import Mechanism, fingerprint
from .._errors import InputError
from .._folders import write_atomic

CHECKPOINT = "checkpoint.json"
#: What identifies the run a checkpoint belongs to (compared on --resume).
_MATCH = ("mechanism", "settings", "steps", "targets")
_MATRICES = ("position", "velocity", "pbest_pos")
_VECTORS = ("pbest_cost", "best_pos")
_SCALARS = ("iteration", "stalled", "limit")


def _targets_digest(targets) -> str:
    values = np.asarray(targets.values, dtype=float).tobytes().hex()
    parts = [targets.kind, targets.name, repr(bool(targets.closed)),
             repr(float(targets.tolerance)), values]  # fmt: skip
    if targets.motors is not None:
        parts.append(np.asarray(targets.motors).tobytes().hex())
    return hashlib.sha256("|".join(parts).encode()).hexdigest()[:16]


def _identity(mech: Mechanism, settings: OptimizerSettings, steps: int, targets):
    return {
        "mechanism": fingerprint(mech),
        "settings": {
            "particles": settings.particles,
            "iterations": settings.iterations,
            "seed": settings.seed,
            "spread": settings.spread,
            "patience": settings.patience,
        },
        "steps": int(steps),
        "targets": _targets_digest(targets),
    }


def _plain(value):
    if isinstance(value, np.ndarray):
        return value.tolist()
    if isinstance(value, (np.floating, np.integer, np.bool_)):
        return value.item()
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value


def save(out: Path, run: SwarmRun, mech, settings, steps: int, targets) -> None:
    """``out/checkpoint.json``, replaced atomically."""
    state = {f.name: _plain(getattr(run, f.name)) for f in dataclasses.fields(run)}
    data = {**_identity(mech, settings, steps, targets), "run": state}
    write_atomic(out / CHECKPOINT, json.dumps(data, allow_nan=True))


def _bad(path: Path, field: str, expected: str) -> InputError:
    return InputError(f"{path}: {field}: expected {expected}")


def _array(path, state, key, shape) -> np.ndarray:
    try:
        value = np.asarray(state[key], dtype=float)
    except (KeyError, TypeError, ValueError):
        raise _bad(path, f"run.{key}", f"an array of shape {shape}") from None
    if value.shape != shape:
        raise _bad(path, f"run.{key}", f"shape {shape}, got {value.shape}")
    if key != "pbest_cost" and not np.all(np.isfinite(value)):
        raise _bad(path, f"run.{key}", "finite numbers")
    return value


def _read(path: Path) -> dict:
    if not path.is_file():
        raise InputError(
            f"{path.parent}: no checkpoint to resume ({CHECKPOINT} missing)"
        )
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise InputError(f"{path}: not a synthesis checkpoint ({err})") from None
    if not isinstance(data, dict) or not isinstance(data.get("run"), dict):
        raise _bad(path, "run", "a checkpoint written by linkopt synthesize")
    return data


def load(out: Path, mech, settings, steps: int, targets) -> SwarmRun:
    """The run checkpointed in ``out``, which must be of this mechanism, settings,
    cycle rows and targets; every field a resumed run reads is checked."""
    path = out / CHECKPOINT
    data = _read(path)
    expected = _identity(mech, settings, steps, targets)
    for key in _MATCH:
        if data.get(key) != expected[key]:
            raise InputError(
                f"{path}: {key}: the checkpoint is of another run ({data.get(key)!r}, "
                f"this one {expected[key]!r}); resume with the same file, targets and "
                "flags, or choose another --out"
            )
    state = data["run"]
    n, p = settings.particles, mech.design.size
    fields = {key: _array(path, state, key, (n, p)) for key in _MATRICES}
    fields["pbest_cost"] = _array(path, state, "pbest_cost", (n,))
    fields["best_pos"] = _array(path, state, "best_pos", (p,))
    for key in _SCALARS:
        value = state.get(key)
        if not isinstance(value, int) or isinstance(value, bool) or value < 0:
            raise _bad(path, f"run.{key}", "a non-negative integer")
        fields[key] = value
    history = state.get("history")
    if not isinstance(history, list) or len(history) != fields["iteration"]:
        raise _bad(path, "run.history", "one record per finished iteration")
    if not all(isinstance(h, dict) for h in history):
        raise _bad(path, "run.history", "records (tables)")
    result = state.get("result_pos")
    fields["result_pos"] = (
        None if result is None else _array(path, state, "result_pos", (p,))
    )
    try:
        rng = np.random.default_rng()
        rng.bit_generator.state = state["rng_state"]
    except (KeyError, TypeError, ValueError):
        raise _bad(path, "run.rng_state", "a numpy generator state") from None
    total = state.get("result_total")
    best = state.get("best_cost")
    if not isinstance(total, (int, float)) or not isinstance(best, (int, float)):
        raise _bad(path, "run.best_cost", "numbers (best_cost, result_total)")
    return SwarmRun(
        **fields,
        best_cost=float(best),
        result_total=float(total) if not math.isnan(total) else math.inf,
        result_feasible=bool(state.get("result_feasible", False)),
        rng_state=state["rng_state"],
        history=tuple(history),
        finished=bool(state.get("finished", False)),
        rounds=(),
    )
