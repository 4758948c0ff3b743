"""Optimisation runs on disk: checkpoint after every iteration, resume, final outputs.

``DIR/checkpoint.json`` holds the whole swarm state (positions, velocities, bests, the
RNG state, the history) and is replaced atomically (write, fsync, rename) after each
finished iteration, so a run killed at any moment resumes from the last finished
iteration and, every step being deterministic, ends exactly as an uninterrupted run
with the same seed. The checkpoint records the mechanism's fingerprint
(:func:`linkopt._engine.model.fingerprint`, the same digest that keys the cache of
traced programs) and the settings; resuming with a different mechanism or other
settings is refused.

Outputs: ``optimized.toml`` (a mechanism file every command accepts), ``history.csv``,
``verification.json`` (``linkopt verify`` on the initial and optimised designs),
``summary.json``, and the figures ``spaces_initial.png``, ``spaces_optimized.png``,
``convergence.png``, ``mechanism.png`` (initial and optimised overlaid). The initial
design's verification and space plot do not depend on the run, so with ``workers`` > 1 a
spawned process makes them while this one makes the optimised design's.
"""

from __future__ import annotations

import dataclasses
import json
import multiprocessing
import os
import time
from collections.abc import Callable
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from .._config import one_blas_thread
from .._engine.model import Mechanism, fingerprint
from .._engine.writer import write_design
from .._errors import InputError
from .evaluation import Evaluation, alpha_minus, evaluate
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
#: The run's array fields, stored in the checkpoint as nested lists.
_ARRAYS = ("position", "velocity", "pbest_pos", "pbest_cost", "best_pos")


def _encode(run: SwarmRun, mech: Mechanism, settings: OptimizerSettings) -> dict:
    arrays = {k: getattr(run, k).tolist() for k in _ARRAYS}
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
        **arrays,
    }


def _decode(data: dict) -> SwarmRun:
    return SwarmRun(
        **{k: np.asarray(data[k], dtype=float) for k in _ARRAYS},
        iteration=data["iteration"],
        best_cost=float(data["best_cost"]),
        rng_state=data["rng_state"],
        history=tuple(data["history"]),
        stalled=data["stalled"],
        finished=data["finished"],
        **_decode_result(data),
    )


def _decode_result(data: dict) -> dict:
    """The returned design's fields; checkpoints written before they existed have
    none."""
    position = data.get("result_pos")
    return {
        "result_pos": None if position is None else np.asarray(position, dtype=float),
        "result_total": float(data.get("result_total", float("inf"))),
        "result_feasible": bool(data.get("result_feasible", False)),
    }


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


def _read_checkpoint(out: Path) -> dict:
    path = out / CHECKPOINT
    try:
        return json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError(
            f"{out}: no checkpoint to resume ({CHECKPOINT} missing)"
        ) from None
    except json.JSONDecodeError as err:
        raise InputError(f"{path}: unreadable checkpoint ({err})") from None


def _check_match(
    path: Path, data: dict, mech: Mechanism, settings: OptimizerSettings
) -> None:
    """Refuse a checkpoint of another mechanism or made with other settings."""
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


def load_checkpoint(
    out: Path, mech: Mechanism, settings: OptimizerSettings
) -> SwarmRun:
    """The run checkpointed in ``out``, which must be of ``mech`` with ``settings``."""
    data = _read_checkpoint(out)
    _check_match(out / CHECKPOINT, data, mech, settings)
    return _decode(data)


def prepare(
    out: Path, mech: Mechanism, settings: OptimizerSettings, resume: bool
) -> SwarmRun:
    """A fresh run, or the checkpointed one with ``resume``."""
    if resume:
        return load_checkpoint(out, mech, settings)
    if (out / CHECKPOINT).exists():
        raise InputError(
            f"{out}: already holds a run; pass --resume to continue it, "
            "or choose another --out"
        )
    out.mkdir(parents=True, exist_ok=True)
    return start(mech, settings)


def _timed(run: SwarmRun, wall_time: float) -> SwarmRun:
    """``run`` with the wall time added to its last history record."""
    *done, last = run.history
    return dataclasses.replace(run, history=(*done, {**last, "wall_time": wall_time}))


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
            run = _timed(run, offset + time.perf_counter() - began)
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


def _optimized_outputs(
    mech: Mechanism,
    out: Path,
    run: SwarmRun,
    design: np.ndarray,
    resolution: int,
    verify_resolution: int | None,
) -> tuple[dict, Evaluation]:
    """The optimised design's verification and evaluation (returned), its space plot,
    the convergence plot and the drawing of both designs (written)."""
    from . import plots

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
    return checked, final


def _design_outputs(
    mech: Mechanism,
    out: Path,
    run: SwarmRun,
    design: np.ndarray,
    resolution: int,
    verify_resolution: int | None,
    workers: int,
) -> tuple[dict, Evaluation]:
    """Both designs' verifications (``{"initial": ..., "optimized": ...}``), the
    optimised design's evaluation, and the figures; with ``workers`` > 1 the initial
    design's in a spawned process (module docstring)."""
    side = (
        ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("spawn"))
        if workers > 1
        else None
    )
    args = (mech, out, resolution, verify_resolution)
    try:
        initial = side.submit(_initial_outputs, *args) if side is not None else None
        checked, final = _optimized_outputs(
            mech, out, run, design, resolution, verify_resolution
        )
        checks = {
            "initial": initial.result()
            if initial is not None
            else _initial_outputs(*args),
            "optimized": checked,
        }
    finally:
        if side is not None:
            side.shutdown(cancel_futures=True)
    return checks, final


def _summary(
    mech: Mechanism,
    run: SwarmRun,
    settings: OptimizerSettings,
    design: np.ndarray,
    final: Evaluation,
    checks: dict,
) -> dict:
    """The contents of ``summary.json``."""
    return {
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
    out = Path(out)
    design = best_design(run)
    optimized = write_design(
        mech,
        design,
        alpha_minus(mech),
        out / "optimized.toml",
        header=(
            f"Optimised by linkopt from {mech.source} "
            f"(seed {settings.seed}, {run.iteration} iterations)."
        ),
    )
    checks, final = _design_outputs(
        mech, out, run, design, resolution, verify_resolution, workers
    )
    (out / "verification.json").write_text(json.dumps(checks, indent=2))
    summary = _summary(mech, run, settings, design, final, checks)
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    summary["optimized_file"] = str(optimized)
    return summary
