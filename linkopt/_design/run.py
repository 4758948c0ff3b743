"""Optimisation runs on disk: checkpoint after every iteration, resume, final outputs.

``DIR/checkpoint.json`` holds the whole swarm state (positions, velocities, bests, the
RNG state, the history) and is replaced atomically (write, fsync, rename) after each
finished iteration, so a run killed at any moment resumes from the last finished
iteration and, every step being deterministic, ends exactly as an uninterrupted run
with the same seed. The checkpoint records the mechanism file's content and the
settings; resuming with different ones is refused.

Outputs: ``optimized.toml`` (a mechanism file every command accepts), ``history.csv``,
``verification.json`` (``linkopt verify`` on the initial and optimised designs),
``summary.json``, and the figures ``spaces_initial.png``, ``spaces_optimized.png``,
``convergence.png``, ``mechanism.png`` (initial and optimised overlaid). The initial
design's verification and space plot do not depend on the run, so with ``workers`` > 1 a
spawned process makes them while this one makes the optimised design's.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing
import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from .._config import one_blas_thread
from .._engine.model import Mechanism
from .._engine.writer import write_design
from .._errors import InputError
from .evaluation import alpha_minus
from .optimizer import OptimizerSettings, SwarmRun, best_design, start, step
from .workers import Workers

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


def _fingerprint(mech: Mechanism) -> str:
    return hashlib.sha256(
        json.dumps(mech.raw, sort_keys=True, default=str).encode()
    ).hexdigest()


def _encode(run: SwarmRun, mech: Mechanism, settings: OptimizerSettings) -> dict:
    arrays = {
        k: getattr(run, k).tolist()
        for k in ("position", "velocity", "pbest_pos", "pbest_cost", "best_pos")
    }
    return {
        "mechanism": _fingerprint(mech),
        "settings": settings.to_dict(),
        "iteration": run.iteration,
        "best_cost": run.best_cost,
        "rng_state": run.rng_state,
        "history": run.history,
        "stalled": run.stalled,
        "finished": run.finished,
        "result_pos": None if run.result_pos is None else run.result_pos.tolist(),
        "result_total": run.result_total,
        "result_feasible": run.result_feasible,
        **arrays,
    }


def _decode(data: dict) -> SwarmRun:
    arr = {
        k: np.asarray(data[k], dtype=float)
        for k in ("position", "velocity", "pbest_pos", "pbest_cost", "best_pos")
    }
    return SwarmRun(
        data["iteration"],
        arr["position"],
        arr["velocity"],
        arr["pbest_pos"],
        arr["pbest_cost"],
        arr["best_pos"],
        float(data["best_cost"]),
        data["rng_state"],
        data["history"],
        data["stalled"],
        data["finished"],
        *_decode_result(data),
    )


def _decode_result(data: dict) -> tuple:
    """The returned design's fields; checkpoints written before they existed have
    none."""
    position = data.get("result_pos")
    return (
        (None if position is None else np.asarray(position, dtype=float)),
        float(data.get("result_total", float("inf"))),
        bool(data.get("result_feasible", False)),
    )


def _atomic_write(path: Path, text: str) -> None:
    tmp = path.with_name(path.name + ".tmp")
    with open(tmp, "w", encoding="utf-8") as f:
        f.write(text)
        f.flush()
        os.fsync(f.fileno())
    os.replace(tmp, path)


def save_checkpoint(
    out: Path, run: SwarmRun, mech: Mechanism, settings: OptimizerSettings
) -> None:
    _atomic_write(
        out / CHECKPOINT, json.dumps(_encode(run, mech, settings), allow_nan=True)
    )
    lines = [",".join(HISTORY_FIELDS)] + [
        ",".join(repr(h[f]) for f in HISTORY_FIELDS) for h in run.history
    ]
    _atomic_write(out / "history.csv", "\n".join(lines) + "\n")


def load_checkpoint(
    out: Path, mech: Mechanism, settings: OptimizerSettings
) -> SwarmRun:
    path = out / CHECKPOINT
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(
            f"{out}: no checkpoint to resume ({CHECKPOINT} missing)"
        ) from None
    except json.JSONDecodeError as err:
        raise InputError(f"{path}: unreadable checkpoint ({err})") from None
    if data["mechanism"] != _fingerprint(mech):
        raise InputError(
            f"{path}: the checkpoint belongs to a different mechanism file; use another --out"
        )
    if data["settings"] != settings.to_dict():
        now = settings.to_dict()
        changed = sorted(
            k
            for k in set(data["settings"]) | set(now)
            if data["settings"].get(k) != now.get(k)
        )
        raise InputError(
            f"{path}: the checkpoint was made with other settings ({', '.join(changed)}); resume with the same flags"
        )
    return _decode(data)


def prepare(
    out: Path, mech: Mechanism, settings: OptimizerSettings, resume: bool
) -> SwarmRun:
    """A fresh run, or the checkpointed one with ``resume``."""
    if resume:
        return load_checkpoint(out, mech, settings)
    if (out / CHECKPOINT).exists():
        raise InputError(
            f"{out}: already holds a run; pass --resume to continue it, or choose another --out"
        )
    out.mkdir(parents=True, exist_ok=True)
    return start(mech, settings)


def optimize(
    mech: Mechanism,
    out: str | Path,
    settings: OptimizerSettings,
    *,
    resume: bool = False,
    progress: Callable[[dict], None] | None = None,
    workers: int = 1,
) -> SwarmRun:
    """Run (or resume) the optimiser, checkpointing after every iteration; ``workers``
    processes share the particles (:mod:`linkopt._design.workers`)."""
    out = Path(out)
    run = prepare(out, mech, settings, resume)
    offset = run.history[-1]["wall_time"] if run.history else 0.0
    began = time.perf_counter()
    with Workers(mech, workers) as pool:
        while not run.finished:
            run = step(mech, run, settings, pool)
            run.history[-1]["wall_time"] = offset + time.perf_counter() - began
            save_checkpoint(out, run, mech, settings)
            if progress is not None:
                progress(run.history[-1])
    return run


def _verification(mech: Mechanism, design, resolution: int | None) -> dict:
    from .verify import verify

    result = verify(mech, design, resolution)
    return {
        k: (v.tolist() if isinstance(v, np.ndarray) else v)
        for k, v in result._asdict().items()
    }


def _has_space_plots(mech: Mechanism) -> bool:
    return mech.num_motors == mech.num_outputs and mech.num_motors in (2, 3)


def _initial_outputs(
    mech: Mechanism, out: Path, resolution: int, verify_resolution: int | None
) -> dict:
    """The initial design's verification (returned) and space plot (written)."""
    from . import plots
    from .evaluation import evaluate

    with one_blas_thread():  # OpenBLAS's spinning threads: linkopt._config
        check = _verification(mech, None, verify_resolution)
        if _has_space_plots(mech):
            plots.plot_spaces(
                mech,
                evaluate(mech),
                out / "spaces_initial.png",
                resolution=resolution,
                title=f"{mech.name}, initial design",
            )
    return check


def write_outputs(
    mech: Mechanism,
    out: str | Path,
    run: SwarmRun,
    settings: OptimizerSettings,
    *,
    resolution: int = 60,
    verify_resolution: int | None = None,
    workers: int = 1,
) -> dict:
    """Optimised file, verification, summary and figures for a finished run.

    With ``workers`` > 1 a spawned process verifies and plots the initial design while
    this one does the optimised design (module docstring)."""
    from . import plots
    from .evaluation import evaluate

    out = Path(out)
    design = best_design(run)
    alpha = alpha_minus(mech)
    optimized = write_design(
        mech,
        design,
        alpha,
        out / "optimized.toml",
        header=f"Optimised by linkopt from {mech.source} (seed {settings.seed}, {run.iteration} iterations).",
    )
    side = (
        ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
        if workers > 1
        else None
    )
    try:
        initial = (
            side.submit(_initial_outputs, mech, out, resolution, verify_resolution)
            if side is not None
            else None
        )
        with one_blas_thread():
            checked = _verification(mech, design, verify_resolution)
            final = evaluate(mech, design)
            if _has_space_plots(mech):
                plots.plot_spaces(
                    mech,
                    final,
                    out / "spaces_optimized.png",
                    resolution=resolution,
                    design=design,
                    title=f"{mech.name}, optimised design",
                )
            plots.plot_convergence(
                run.history, out / "convergence.png", title=f"{mech.name}: optimisation"
            )
            plots.plot_mechanism(
                mech,
                out / "mechanism.png",
                designs={"initial": None, "optimised": design},
            )
        checks = {
            "initial": initial.result()
            if initial is not None
            else _initial_outputs(mech, out, resolution, verify_resolution),
            "optimized": checked,
        }
    finally:
        if side is not None:
            side.shutdown(cancel_futures=True)
    (out / "verification.json").write_text(json.dumps(checks, indent=2))
    summary = {
        "mechanism": mech.source,
        "iterations": run.iteration,
        "evaluations": run.history[-1]["evaluations"],
        "wall_time": run.history[-1]["wall_time"],
        "design": dict(zip(mech.design.names, map(float, design))),
        "initial_design": dict(zip(mech.design.names, map(float, mech.design.p0))),
        "f_design": float(final.f_design),
        "reach": float(final.reach),
        "singularity": float(final.singularity),
        "regularizer": float(final.regularizer),
        "verified": checks["optimized"]["passed"],
        "initial_verified": checks["initial"]["passed"],
        "settings": settings.to_dict(),
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    summary["optimized_file"] = str(optimized)
    return summary
