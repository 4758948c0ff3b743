"""Optimisation runs on disk: checkpoint after every iteration, resume, final outputs.

``DIR/checkpoint.json`` holds the whole swarm state (positions, velocities, bests, the
RNG state, the history) and is replaced atomically (write, fsync, rename) after each
finished iteration, so a run killed at any moment resumes from the last finished
iteration and, every step being deterministic, ends exactly as an uninterrupted run
with the same seed. The checkpoint records the mechanism's fingerprint
(:func:`linkopt._engine.model.fingerprint`, the same digest that keys the cache of
traced programs) and the settings; resuming with a different mechanism or other
settings is refused, and so is a checkpoint whose fields are not what a run writes
(:mod:`linkopt._design.checkpoint`), before any work starts.

A run folder belongs to one process at a time: :func:`optimize` and
:func:`write_outputs` hold an exclusive lock on it (:mod:`linkopt._folders`; a second
process gets :class:`~linkopt.InputError` naming the holder), temporary files have
unique names, and the final outputs are staged and moved in together once all are
written, ``summary.json`` last, so a failed or killed ``write_outputs`` leaves the
folder's earlier outputs (or none) rather than a part of new ones.

Before a run stops it verifies its design, and goes on with added IK targets where
verification fails (:mod:`linkopt._design.rounds`); the checkpoint holds the rounds, so
a resumed run evaluates the same targets.

Outputs: ``optimized.toml`` (a mechanism file every command accepts), ``history.csv``
(with ``[collision]`` enabled, also the collision columns: :mod:`.collision`),
``verification.json`` (``linkopt verify`` on the initial and optimised designs),
``summary.json``, ``optimized.xml`` (the optimised design for MuJoCo,
:mod:`linkopt._export.mjcf`), and the figures that :func:`write_outputs`'s ``figures``
draws from a :class:`RunFigures` per design. This layer draws nothing: the drawing layer
sits above it (:mod:`linkopt._draw.run_folder`, whose ``write_outputs`` is the public
one), in three calls: the file's design's own figures (its space plot), both designs'
motions, and the optimised design's figures (its space plot, convergence, mechanism).
The work is split between two processes: with ``workers`` > 1 a side process (one the
optimiser's ``Workers`` handed back warm, :func:`linkopt._design.ahead.side`, else a
spawned one) solves both designs' motions while this one draws the optimised design's
figures; the motions' call leaves their two GIFs to draw (:data:`Figures`): the side
process draws the first as soon as it has made them, this one the last
(:func:`_draw_side`).
The file's design's own figures (:func:`initial_figures`: its space plot) depend on
the file alone: the command line has the side process draw them while this one runs
the run's last verification round (:func:`linkopt._design.ahead.early`, where that
process would otherwise wait), and :func:`write_outputs` takes them from there;
without them this process draws them too. The files are the same with one process;
an error in an output is raised here as :class:`OutputError` naming it
(:func:`writing`), whichever process made it.
"""

from __future__ import annotations

import dataclasses
import json
import math
import multiprocessing
import tempfile
import time
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from pathlib import Path

import numpy as np

from .._cache import requested
from .._config import adopt, one_blas_thread
from .._engine.model import Mechanism
from .._errors import InputError
from .._files.writer import write_design
from .._folders import check_path, run_folder, staged, write_atomic
from . import ahead
from .checkpoint import CHECKPOINT, HISTORY_FIELDS, check_match, decode, encode, read
from .collision import history_fields, summary_entry
from .evaluation import Evaluation, alpha_minus, capped, evaluate_in_batch, targets
from .on_bounds import BOUND_TOLERANCE, on_bounds
from .optimizer import OptimizerSettings, SwarmRun, best_design, start, step
from .outputs import Figures, OutputError, RunFigures, writing  # noqa: F401 (their home)
from .rounds import verification_round, wants_round, with_targets
from .workers import Workers, chunk_slices


def save_checkpoint(
    out: Path, run: SwarmRun, mech: Mechanism, settings: OptimizerSettings
) -> None:
    """``checkpoint.json`` and ``history.csv``, each replaced atomically."""
    write_atomic(
        out / CHECKPOINT, json.dumps(encode(run, mech, settings), allow_nan=True)
    )
    fields = history_fields(mech, HISTORY_FIELDS)
    if any("refused" in h for h in run.history):  # designs that change the mobility
        fields = [*fields, "refused", "refused_reason"]
    lines = [",".join(fields)] + [
        ",".join(_cell(h.get(f, _UNREFUSED.get(f, math.nan))) for f in fields)
        for h in run.history
    ]
    write_atomic(out / "history.csv", "\n".join(lines) + "\n")


#: ``history.csv``'s mobility columns in an iteration that refused no design.
_UNREFUSED = {"refused": 0, "refused_reason": ""}


def _cell(value) -> str:
    """A ``history.csv`` cell: a number as ``repr``, a text quoted (RFC 4180)."""
    if isinstance(value, str):
        return '"' + value.replace('"', '""') + '"'
    return repr(value)


def load_checkpoint(
    out: Path, mech: Mechanism, settings: OptimizerSettings
) -> SwarmRun:
    """The run checkpointed in ``out``, which must be of ``mech`` with ``settings``;
    every field is checked (:mod:`linkopt._design.checkpoint`)."""
    data = read(out)
    check_match(out / CHECKPOINT, data, mech, settings)
    return decode(out / CHECKPOINT, data, mech, settings)


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


@contextmanager
def locked_run_folder(
    out: str | Path, resume: bool = False, where: str = "out"
) -> Iterator[Path]:
    """Hold the run folder ``out`` for the block: checked, created unless ``resume``
    (which needs it to exist), and locked against other processes
    (:mod:`linkopt._folders`); ``where`` names it in error messages."""
    out = check_path(out, where)
    if resume and not out.exists():
        raise InputError(f"{out}: no checkpoint to resume ({CHECKPOINT} missing)")
    with run_folder(out, where):
        yield out


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
    pool: Callable[[Mechanism], Workers] | None = None,
) -> SwarmRun:
    """Run (or resume) the optimiser, checkpointing after every iteration and every
    verification round (:mod:`linkopt._design.rounds`); ``workers`` processes share
    the particles (:mod:`linkopt._design.workers`), or ``pool(mechanism)`` evaluates
    them (an object with :class:`~linkopt._design.workers.Workers`' interface, such as
    a Dask cluster's :class:`~linkopt._design.cluster.ClusterWorkers`). ``progress``
    gets each iteration's history record and each round's record (which has a
    ``"passed"`` key).

    ``out`` is locked for the call (:func:`locked_run_folder`): another process on it
    gets :class:`~linkopt.InputError`. A checkpoint to resume is checked in full before
    any evaluation, and so is a rest pose that gives no α₋
    (:func:`linkopt._design.evaluation.alpha_minus`), here rather than in a worker."""
    alpha_minus(mech)
    with locked_run_folder(out, resume) as out:
        run = prepare(out, mech, settings, resume)
        offset = run.history[-1]["wall_time"] if run.history else 0.0
        began = time.perf_counter()
        while True:
            current = with_targets(mech, run.added_targets)
            if not run.finished:
                chunks = Workers(current, workers) if pool is None else pool(current)
                with chunks:
                    while not run.finished:
                        fresh = run.iteration == 0 and current is mech
                        run = step(current, run, settings, chunks)
                        if fresh:
                            _give_file_design(mech, chunks)
                        run = _timed(run, offset + time.perf_counter() - began)
                        save_checkpoint(out, run, mech, settings)
                        if progress is not None:
                            progress(run.history[-1])
            if not wants_round(run, settings):
                return run
            with one_blas_thread():
                run = verification_round(current, run, settings)
            save_checkpoint(out, run, mech, settings)
            if progress is not None:
                progress(run.rounds[-1])


def _give_file_design(mech: Mechanism, chunks) -> None:
    """The first iteration's evaluation of the file's design (the swarm's first
    particle is ``p₀`` exactly, and a design's lanes do not depend on the others in a
    batch: :func:`~linkopt._design.evaluation.evaluate_in_batch`) to the file's
    design's figures made ahead (:func:`initial_figures`,
    :func:`linkopt._design.ahead.early_given`), which then do not evaluate it again
    in the process that draws them. Only from this process's own chunk of a
    :class:`Workers`; nothing when that chunk did not start at ``p₀``."""
    first = chunks.first if isinstance(chunks, Workers) else None
    if first is not None and np.array_equal(first[0], mech.design.p0):
        ahead.early_given(evaluation=first[1])


def _verification(mech: Mechanism, design, resolution: int | None) -> dict:
    from .verify import verify

    return verify(mech, design, resolution).as_json()


def _announce(progress, stage: str) -> None:
    """A stage of the final outputs, as a ``{"stage"}`` progress record."""
    if progress is not None:
        progress({"stage": stage})


def _side_pool(workers: int) -> ProcessPoolExecutor | None:
    """The process that draws the file's design's figures beside this one when the run
    has ``workers`` > 1: one the optimiser's ``Workers`` handed back, warm
    (:func:`linkopt._design.ahead.side`), else a spawned one."""
    if workers < 2:
        return None
    return ahead.side() or ProcessPoolExecutor(
        1,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=adopt,
        initargs=(requested(),),
    )


def _draw_side(figures: Figures, job: RunFigures) -> tuple:
    """The call of ``figures`` with ``job``, with OpenBLAS held to one thread
    (:mod:`linkopt._config`); run in the side process or, without one, here. Of the
    drawings it leaves (:data:`Figures`) it runs all but the last at once, where it
    made them, and returns the last for the caller (:func:`_side_result`): the side
    process is done with the motions before this one is done with the optimised
    design's figures, so it draws its share while it would wait (the main job, idle
    2-core machine: its GIF drawn after that wait ended the outputs 0.6 s later)."""
    with one_blas_thread():
        drawings = tuple(figures(job) or ())
        for drawing in drawings[:-1]:
            drawing()
    return drawings[-1:]


def _drawn(drawing: Callable[[], None]) -> None:
    """One drawing left by a call of the figures (:data:`Figures`), with OpenBLAS held
    to one thread."""
    with one_blas_thread():
        drawing()


def _submit(side: ProcessPoolExecutor | None, fn, *args):
    """The side process's future of ``fn(*args)``, or None: no side process, or it
    died before taking the job (then the caller runs it here)."""
    if side is None:
        return None
    try:
        return side.submit(fn, *args)
    except (BrokenProcessPool, RuntimeError):  # broken, or shut down
        return None


def _side_result(future, figures: Figures, job: RunFigures, progress=None) -> None:
    """Wait for the side process's call of ``figures`` with ``job``; an error there is
    raised here as it was raised there (naming its output, :func:`writing`). When
    that process died (killed, or crashed), or there was none, the call is made here:
    a lost side process costs time, never the run. Of the drawings the call left
    (:data:`Figures`: the motions' GIFs) all but the last are drawn where the call
    ran (:func:`_draw_side`), the last here."""
    job = dataclasses.replace(job, progress=progress)  # where it is drawn here
    for drawing in _there_or_here(future, _draw_side, figures, job):
        _drawn(drawing)


def _there_or_here(future, fn, *args):
    """``future``'s result, the side process's call of ``fn(*args)`` (an error there
    is raised here as it was raised there), or ``fn(*args)`` called here when there
    was no such call (``future`` None) or its process died."""
    if future is not None:
        try:
            return future.result()
        except BrokenProcessPool:
            pass
    return fn(*args)


def last_round_verification(
    mech: Mechanism, run: SwarmRun, design: np.ndarray, verify_resolution: int | None
) -> dict | None:
    """The verification of ``design`` by the run's last round, if it verified this
    design at the resolution asked for (rounds verify at the default one,
    :func:`linkopt._design.verify.default_resolution`, so a ``verify_resolution``
    equal to it is served too). A round's mechanism differs from ``mech`` only in
    IK targets, which verification does not use."""
    from .verify import default_resolution

    default = default_resolution(mech)
    if not run.rounds or verify_resolution not in (None, default):
        return None
    last = run.rounds[-1]
    return last["verification"] if last["design"] == design.tolist() else None


def swarm_rows(particles: int, workers: int) -> int:
    """The rows of the swarm's evaluation program with ``workers`` processes (its first
    chunk's), the shape the final outputs evaluate designs in, to share it."""
    first = chunk_slices(particles, workers)[0]
    return first.stop - first.start


def initial_figures(
    mech: Mechanism,
    rows: int,
    resolution: int | None,
    figures: Figures,
    evaluation: Evaluation | None = None,
) -> dict[str, bytes]:
    """The file's design's own figures (the call of ``figures`` with ``design`` and
    ``optimized`` None: its space plot), which depend on the file alone, not on the
    run: drawn before the run ends where a process is free for them
    (:func:`linkopt._design.ahead.early`: the command line's worker, during the last
    verification round), else by :func:`write_outputs`. They are drawn into a
    temporary folder and returned as bytes by file name. ``evaluation``: the file's
    design's, where the run has it (:func:`_give_file_design`); else the figures
    evaluate it."""
    with one_blas_thread():
        with tempfile.TemporaryDirectory(prefix="linkopt-initial-") as folder:
            folder = Path(folder)
            job = RunFigures(mech, mech, folder, None, evaluation, rows, (), resolution)
            figures(job)
            return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _early_initial(args: tuple) -> Future | None:
    """The future of :func:`initial_figures` started ahead with ``args``
    (:func:`linkopt._design.ahead.early_result`), if it was started with those; the
    mechanism must be the same object."""
    started = ahead.early_result()
    if started is None:
        return None
    given, future = started
    if len(given) != len(args) or given[0] is not args[0] or given[1:] != args[1:]:
        future.cancel()  # another run's, or other settings: drawn here instead
        return None
    return future


def _initial_files(future: Future, args: tuple) -> dict[str, bytes]:
    """:func:`initial_figures`: ``future``'s result (an error there is raised here,
    naming its output), or drawn here when its process died."""
    return _there_or_here(future, initial_figures, *args)


def _design_outputs(
    mech: Mechanism,
    current: Mechanism,
    out: Path,
    run: SwarmRun,
    design: np.ndarray,
    resolution: int | None,
    verify_resolution: int | None,
    workers: int,
    figures: Figures | None,
    progress: Callable[[dict], None] | None = None,
    side: ProcessPoolExecutor | None = None,
) -> tuple[dict, Evaluation]:
    """Both designs' verifications (``{"initial": ..., "optimized": ...}``), the
    optimised design's evaluation (with the targets of ``current``: the file's and the
    run's rounds'), and the figures: the motions of both designs in the ``side``
    process while this one verifies both designs (it has the verification's programs
    loaded from the run's last round) and draws the optimised design's; the file's
    design's own figures made ahead (:func:`initial_figures`), else drawn here after
    the optimised design's; without ``side`` all here. The figures are the same
    either way."""
    rows = swarm_rows(len(run.position), workers)
    initial_args = (mech, rows, resolution, figures)
    early = _early_initial(initial_args) if figures is not None else None
    side_job = None
    if figures is not None:
        side_job = RunFigures(mech, current, out, None, None, rows, (), resolution)
        side_job = dataclasses.replace(side_job, optimized=design)
    future = None
    if side_job is not None:
        future = _submit(side, _draw_side, figures, side_job)
    with one_blas_thread():  # OpenBLAS's spinning threads: linkopt._config
        with writing("verification.json (optimised design)"):
            checked = last_round_verification(current, run, design, verify_resolution)
            if checked is None:
                _announce(progress, "verifying the optimised design")
                checked = _verification(current, design, verify_resolution)
        with writing("verification.json (initial design)"):
            _announce(progress, "verifying the initial design")
            initial = _verification(mech, None, verify_resolution)
        with writing("summary.json (the optimised design's evaluation)"):
            final = evaluate_in_batch(current, design, rows)
    if figures is not None:
        job = RunFigures(mech, current, out, design, final, rows, run.history)
        figures(dataclasses.replace(job, resolution=resolution, progress=progress))
        if early is None:  # the file's design's own figures, here
            own = dataclasses.replace(side_job, optimized=None, progress=progress)
            with one_blas_thread():
                figures(own)
        else:
            for name, data in _initial_files(early, initial_args).items():
                (out / name).write_bytes(data)
        _side_result(future, figures, side_job, progress)
    return {"initial": initial, "optimized": checked}, final


def _summary(
    mech: Mechanism,
    run: SwarmRun,
    settings: OptimizerSettings,
    design: np.ndarray,
    final: Evaluation,
    checks: dict,
) -> dict:
    """The contents of ``summary.json``; ``f_design`` and its parts are the run's
    last history record's, the returned design's numbers that the progress line and
    ``history.csv`` give (:func:`linkopt._design.optimizer.record_iteration`)."""
    last = run.history[-1]
    return {
        "mechanism": mech.source,
        "iterations": run.iteration,
        "evaluations": run.history[-1]["evaluations"],
        "wall_time": run.history[-1]["wall_time"],
        "design": dict(zip(mech.design.names, map(float, design))),
        "initial_design": dict(zip(mech.design.names, map(float, mech.design.p0))),
        "f_design": float(last["best_f_design"]),
        "reach": float(last["reach"]),
        "singularity": float(last["singularity"]),
        "regularizer": float(last["regularizer"]),
        "at_bounds": on_bounds(mech, design),
        "bound_tolerance": BOUND_TOLERANCE,
        "verified": checks["optimized"]["passed"],
        "initial_verified": checks["initial"]["passed"],
        "verification_rounds": [
            {k: v for k, v in r.items() if k != "verification"} for r in run.rounds
        ],
        "targets": len(targets(mech)),
        "added_targets": [list(t) for t in run.added_targets],
        "capped_samples": dict(zip(("ik", "adversarial"), capped(mech, final))),
        **summary_entry(mech, final, design, checks),
        "settings": settings.to_dict(),
    }


@contextmanager
def _ending(pool: ProcessPoolExecutor | None) -> Iterator[ProcessPoolExecutor | None]:
    """``pool`` for the block, ended after it (its queued work cancelled)."""
    try:
        yield pool
    finally:
        if pool is not None:
            pool.shutdown(cancel_futures=True)


def _design_files(mech, current, design, stage: Path, settings, run) -> None:
    """``optimized.toml`` and ``optimized.xml`` (the design for MuJoCo,
    :mod:`linkopt._export.mjcf`) in ``stage``."""
    with writing("optimized.toml"):
        write_design(
            current,
            design,
            alpha_minus(mech),
            stage / "optimized.toml",
            header=(
                f"Optimised by linkopt from {mech.source} "
                f"(seed {settings.seed}, {run.iteration} iterations)."
            ),
        )
    from .._export.mjcf import export_mjcf

    with writing("optimized.xml"):
        export_mjcf(current, stage / "optimized.xml", design)


def write_outputs(
    mech: Mechanism,
    out: str | Path,
    run: SwarmRun,
    settings: OptimizerSettings,
    *,
    figures: Figures | None,
    resolution: int | None = None,
    verify_resolution: int | None = None,
    workers: int = 1,
    progress: Callable[[dict], None] | None = None,
) -> dict:
    """Optimised file, verification, summary and, drawn by ``figures`` (None: no
    figures), the figures of a finished run; the public
    :func:`linkopt.write_outputs` passes the drawing layer's
    (:func:`linkopt._draw.run_folder.draw_run_figures`).

    With ``workers`` > 1 a side process draws the file's design's figures while this
    one does the rest (module docstring). ``out`` is locked for the
    call, and the files are staged: they replace the folder's earlier ones only once
    all are written, ``summary.json`` last (:func:`linkopt._folders.staged`), so a
    failure leaves no ``optimized.toml`` that looks like this run's result.
    ``resolution`` and ``progress`` are handed to ``figures``; ``progress`` also gets
    ``{"stage"}`` records as each verification starts."""
    out = Path(out)
    design = best_design(run)
    if design is None:
        raise InputError(f"{out}: the run has not finished an iteration yet")
    current = with_targets(mech, run.added_targets)
    with (
        locked_run_folder(out),
        staged(out, marker="summary.json") as stage,
        _ending(_side_pool(workers) if figures is not None else None) as side,
    ):
        _design_files(mech, current, design, stage, settings, run)
        checks, final = _design_outputs(
            mech,
            current,
            stage,
            run,
            design,
            resolution,
            verify_resolution,
            workers,
            figures,
            progress,
            side,
        )
        (stage / "verification.json").write_text(json.dumps(checks, indent=2))
        summary = _summary(current, run, settings, design, final, checks)
        (stage / "summary.json").write_text(json.dumps(summary, indent=2))
    summary["optimized_file"] = str(out / "optimized.toml")
    return summary
