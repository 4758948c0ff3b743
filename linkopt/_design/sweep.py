"""Many independent optimisations of one mechanism, one per seed (``linkopt sweep``).

Each seed is a whole run (:func:`linkopt._design.run.optimize` and
:func:`~linkopt._design.run.write_outputs`) in its own run folder ``DIR/seed_NNN``, so
each is resumable by itself: a seed whose ``summary.json`` exists is finished and only
read back; a seed with a checkpoint resumes from it (and ends as an uninterrupted run
would, :mod:`linkopt._design.run`); any other starts afresh. A sweep killed at any
moment and rerun with the same command therefore recomputes nothing that finished.

Where the runs go is the caller's: :func:`run_seed` is one seed in the calling process
(``workers`` processes sharing its particles), and the same function with
``in_process=True`` is the task a Dask worker runs for one seed (``linkopt sweep
--scheduler``, one optimisation per task). There the ``workers`` chunks of each
iteration are evaluated one after another in the worker's process
(:class:`InProcessChunks`; Dask's worker processes are daemons and may not start
others), so a seed's run is bit-identical to the local sweep's and to ``linkopt
optimize --seed S --workers N`` (the chunks, not the processes, fix the numbers:
:mod:`linkopt._design.workers`).
On a cluster ``DIR`` must be a path every worker can write, the same on each (a shared
file system); the mechanism travels pickled with the task.

``DIR/summary.csv`` has one row per finished seed, and ``DIR/best.toml`` is the
``optimized.toml`` of the best verified run: ranked first by whether its ``f_design`` is
at most the settings' ``tolerance`` and then by total (``f_design`` + regulariser), the
order in which a run ranks its own designs (:mod:`linkopt._design.optimizer`); ties go
to the lower seed. Without a verified run there is no ``best.toml`` (an older one is
removed) and :func:`write_summary` says so.
"""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Callable
from pathlib import Path

import jax
import numpy as np
from jaxtyping import Array, Float

from .._cache import Use
from .._config import adopt, one_blas_thread
from .._engine.model import Mechanism
from .._folders import write_atomic
from .checkpoint import CHECKPOINT
from .evaluation import Evaluation, evaluate
from .optimizer import OptimizerSettings, SwarmRun
from .run import Figures, locked_run_folder, optimize, write_outputs
from .workers import Workers, concatenate

SUMMARY_FIELDS = (
    "seed",
    "iterations",
    "seconds",
    "f_design",
    "regularizer",
    "verified",
)
BEST = "best.toml"


class InProcessChunks(Workers):
    """:class:`~linkopt._design.workers.Workers`' ``count`` chunks, all evaluated in
    this process: the numbers of a ``count``-process run, without the processes."""

    def _start_pool(self) -> None:
        return None

    def evaluate(self, designs: Float[Array, "N n_p"]) -> Evaluation:
        designs = np.asarray(designs, dtype=float)
        with one_blas_thread():
            return concatenate(
                [
                    jax.tree_util.tree_map(np.asarray, evaluate(self.mech, designs[c]))
                    for c in self._chunks(len(designs))
                ]
            )


def optimize_with_pool(
    pool: Callable[[Mechanism], Workers],
    mech: Mechanism,
    out: str | Path,
    settings: OptimizerSettings,
    *,
    resume: bool = False,
    progress: Callable[[dict], None] | None = None,
) -> SwarmRun:
    """:func:`linkopt._design.run.optimize` with the pool ``pool(mechanism)`` (a
    :class:`~linkopt._design.workers.Workers` or one with its interface) in place of
    ``Workers(mechanism, workers)``: the same checkpoints, resume, verification rounds
    and progress records."""
    return optimize(mech, out, settings, resume=resume, progress=progress, pool=pool)


def parse_seeds(text: str) -> list[int]:
    """``"A:B"`` (seeds A to B-1, as a Python range) or a comma list ``"0,3,7"``;
    ``ValueError`` with the reason otherwise."""
    if ":" in text:
        first, _, stop = text.partition(":")
        seeds = list(range(int(first), int(stop)))
    else:
        seeds = [int(s) for s in text.split(",") if s.strip()]
    if not seeds:
        raise ValueError(f"no seeds in {text!r}")
    if min(seeds) < 0:
        raise ValueError(f"seeds must be non-negative, got {min(seeds)}")
    if len(set(seeds)) != len(seeds):
        raise ValueError(f"a seed is repeated in {text!r}")
    return seeds


def seed_folder(out: Path, seed: int) -> Path:
    return Path(out) / f"seed_{seed:03d}"


def _row(seed: int, summary: dict) -> dict:
    return {
        "seed": seed,
        "iterations": summary["iterations"],
        "seconds": summary["wall_time"],
        "f_design": summary["f_design"],
        "regularizer": summary["regularizer"],
        "verified": summary["verified"],
    }


def finished_row(out: Path, seed: int) -> dict | None:
    """The summary row of a seed whose run folder is complete, else None."""
    path = seed_folder(out, seed) / "summary.json"
    if not path.exists():
        return None
    return _row(seed, json.loads(path.read_text()))


def run_seed(
    mech: Mechanism,
    out: str | Path,
    settings: OptimizerSettings,
    *,
    figures: Figures | None,
    workers: int = 1,
    resolution: int | None = None,
    in_process: bool = False,
    caches: Use | None = None,
) -> dict:
    """One seed's run (``settings.seed``) in ``out/seed_NNN``, finished, resumed or
    started (module docstring), its ``workers`` chunks in as many processes or, with
    ``in_process``, all in this one, its figures drawn by ``figures``
    (:func:`linkopt._design.run.write_outputs`); its summary row, with ``"computed"``
    False when the folder was already complete. ``caches``: those of the process that
    sent the run (:func:`linkopt._config.adopt`), where it runs on a Dask worker."""
    adopt(caches)
    out = Path(out)
    seed = settings.seed
    done = finished_row(out, seed)
    if done is not None:
        return {**done, "computed": False}
    folder = seed_folder(out, seed)
    resume = (folder / CHECKPOINT).exists()
    with locked_run_folder(folder, resume, f"{out}/{folder.name}"):
        if in_process:
            run = optimize_with_pool(
                lambda current: InProcessChunks(current, workers),
                mech,
                folder,
                settings,
                resume=resume,
            )
        else:
            run = optimize(mech, folder, settings, resume=resume, workers=workers)
        summary = write_outputs(
            mech,
            folder,
            run,
            settings,
            figures=figures,
            resolution=resolution,
            workers=1 if in_process else workers,
        )
    return {**_row(seed, summary), "computed": True}


def seed_settings(settings: OptimizerSettings, seed: int) -> OptimizerSettings:
    return dataclasses.replace(settings, seed=seed)


def _rank(row: dict, tolerance: float) -> tuple:
    return (
        row["f_design"] > tolerance,
        row["f_design"] + row["regularizer"],
        row["seed"],
    )


def write_summary(out: Path, rows: list[dict], tolerance: float) -> int | None:
    """``summary.csv`` (rows by seed) and ``best.toml``; the best verified seed, or
    None when no run verified (and no ``best.toml`` is left)."""
    rows = sorted(rows, key=lambda r: r["seed"])
    lines = [",".join(SUMMARY_FIELDS)] + [
        ",".join(
            repr(r[f]) if isinstance(r[f], float) else str(r[f]) for f in SUMMARY_FIELDS
        )
        for r in rows
    ]
    write_atomic(out / "summary.csv", "\n".join(lines) + "\n")
    verified = [r for r in rows if r["verified"]]
    if not verified:
        (out / BEST).unlink(missing_ok=True)
        return None
    best = min(verified, key=lambda r: _rank(r, tolerance))
    text = (seed_folder(out, best["seed"]) / "optimized.toml").read_text()
    write_atomic(out / BEST, text)
    return best["seed"]
