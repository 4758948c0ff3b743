"""A run folder's figures, and the public :func:`write_outputs` that asks for them.

The run folder is written by the design layer
(:func:`linkopt._design.run.write_outputs`), which may not import this layer; it takes
the drawing as an argument, and :func:`draw_run_figures` is the one call it makes, once
per design. The initial design's
call draws ``spaces_initial.png`` and ``motion_initial.gif`` / ``motion_optimized.gif``
(mechanisms with 1-3 motors; in a side process when the run has workers); the
optimised design's draws ``spaces_optimized.png``, ``convergence.png`` and
``mechanism.png`` (both designs overlaid). An error in a figure names it
(:func:`linkopt._design.run.writing`), in whichever process it was drawn. Space plots
are drawn for 2 or 3 motors and as many outputs.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

from .._config import one_blas_thread
from .._design import run as run_folder
from .._design.optimizer import OptimizerSettings, SwarmRun
from .._design.run import writing
from .._engine.model import Mechanism


def has_space_plots(mech: Mechanism) -> bool:
    """Whether a run folder holds space plots: 2 or 3 motors and as many outputs."""
    return mech.num_motors == mech.num_outputs and mech.num_motors in (2, 3)


def _prefixed(progress, prefix: str):
    """``progress`` with ``prefix`` before each record's stage."""
    if progress is None:
        return None
    return lambda record: progress({**record, "stage": prefix + record["stage"]})


def draw_run_figures(job: run_folder.RunFigures) -> None:
    """The figures of ``job``'s design in ``job.out`` (module docstring)."""
    if job.design is None:
        _initial(job)
    else:
        _optimized(job)


def _initial(job: run_folder.RunFigures) -> None:
    """``spaces_initial.png`` and, given the optimised design (``job.optimized``), the
    motions of both designs: with workers, the run's side process draws these while
    the main one draws :func:`_optimized`'s (:func:`linkopt._design.run.write_outputs`);
    the two calls together take about as long."""
    from .._design.evaluation import evaluate_in_batch
    from .space_plots import plot_spaces

    mech = job.mech
    if has_space_plots(mech):
        with one_blas_thread(), writing("spaces_initial.png"):
            plot_spaces(
                mech,
                evaluate_in_batch(mech, None, job.rows),
                job.out / "spaces_initial.png",
                resolution=job.resolution,
                title=f"{mech.name}, initial design",
                progress=_prefixed(job.progress, "initial design, "),
            )
    if job.optimized is not None:
        from .animation import write_run_motions

        with writing("motion_initial.gif, motion_optimized.gif"):
            write_run_motions(job.mech, job.current, job.out, job.optimized)


def _optimized(job: run_folder.RunFigures) -> None:
    """The space plot solves with the file's mechanism: the rounds' targets, which the
    figure does not use, are part of the fingerprint that keys every compiled program,
    so it shares the initial design's plot's programs."""
    from .plots import plot_convergence, plot_mechanism
    from .space_plots import plot_spaces

    current = job.current
    with one_blas_thread():
        if has_space_plots(current):
            with writing("spaces_optimized.png"):
                plot_spaces(
                    job.mech,
                    job.evaluation,
                    job.out / "spaces_optimized.png",
                    resolution=job.resolution,
                    design=job.design,
                    title=f"{current.name}, optimised design",
                    progress=_prefixed(job.progress, "optimised design, "),
                )
        with writing("convergence.png"):
            plot_convergence(
                job.history,
                job.out / "convergence.png",
                title=f"{current.name}: optimisation",
            )
        with writing("mechanism.png"):
            plot_mechanism(
                current,
                job.out / "mechanism.png",
                designs={"initial": None, "optimised": job.design},
            )


def write_outputs(
    mech: Mechanism,
    out: str | Path,
    run: SwarmRun,
    settings: OptimizerSettings,
    *,
    resolution: int | None = None,
    verify_resolution: int | None = None,
    workers: int = 1,
    progress: Callable[[dict], None] | None = None,
) -> dict:
    """Optimised file, verification, summary and figures for a finished run.

    With ``workers`` > 1 a side process draws the initial design's space plot and the
    motions while this one verifies both designs and draws the rest. ``out`` is
    locked for the call, and the files are staged: they replace the folder's earlier
    ones only once all are written, ``summary.json`` last
    (:func:`linkopt._folders.staged`), so a failure leaves no ``optimized.toml`` that
    looks like this run's result. ``resolution``: the space plots' (default by the
    number of outputs, :func:`linkopt._design.maps.plot_resolution`); ``progress``
    gets ``{"stage"}`` records as each verification starts and the maps' wave records
    (not those of the side process)."""
    return run_folder.write_outputs(
        mech,
        out,
        run,
        settings,
        figures=draw_run_figures,
        resolution=resolution,
        verify_resolution=verify_resolution,
        workers=workers,
        progress=progress,
    )
