"""A run folder's figures, and the public :func:`write_outputs` that asks for them.

The run folder is written by the design layer
(:func:`linkopt._design.run.write_outputs`), which may not import this layer; it takes
the drawing as an argument, and :func:`draw_run_figures` is the one call it makes,
three times: the file's design's call draws ``spaces_initial.png`` (made ahead, while
the run's last verification round runs, where the command line has a process free:
:func:`linkopt._design.run.initial_figures`); the motions' call draws
``motion_initial.gif`` / ``motion_optimized.gif`` (mechanisms with 1-3 motors; solved
in a side process when the run has workers, which then draws the first GIF while the
main process draws the second); the optimised design's draws
``spaces_optimized.png``, ``convergence.png`` and ``mechanism.png`` (both designs
overlaid). An error in a figure names it (:func:`linkopt._design.run.writing`), in
whichever process it was drawn. Space plots are drawn for 2 or 3 motors and as many
outputs.
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


def draw_run_figures(job: run_folder.RunFigures) -> tuple:
    """The figures of ``job`` in ``job.out`` (module docstring): the motions when it
    has ``optimized`` (returned as the drawings left, :data:`~.run_folder.Figures`),
    else its design's own."""
    if job.design is None and job.optimized is not None:
        return _motions(job)
    if job.design is None:
        _initial(job)
    else:
        _optimized(job)
    return ()


#: The run folder's browser view (:func:`draw_run_figures_and_view`).
VIEW_FILE = "view.html"


def draw_run_figures_and_view(job: run_folder.RunFigures) -> tuple:
    """:func:`draw_run_figures`, and on the optimised design's job ``view.html`` too
    (:func:`run_view`): ``linkopt optimize`` passes it, so the page's grids are solved
    while the side process solves the motions rather than after them."""
    left = draw_run_figures(job)
    if job.design is not None:
        run_view(job.mech, job.out)
    return left


def run_view(mech: Mechanism, out: Path) -> bool:
    """``view.html`` in the run folder (or stage) ``out`` that holds
    ``optimized.toml``: the page of that file's mechanism at the initial design
    (``mech``'s, the file the run started from: ``summary.json``'s
    ``initial_design``) and at the optimised one, at the default resolution, as
    ``linkopt view DIR`` draws it. One that cannot be written (an error naming its
    file) is not: False, and the caller writes it or says why
    (:func:`linkopt._cli.view.write_run_view`)."""
    import numpy as np

    from .._errors import LinkoptError
    from .._files.fields import parse_text
    from .._files.loader import build
    from .view import write_page

    optimized = out / "optimized.toml"
    try:
        shown = build(parse_text(optimized), str(optimized))
        initial = dict(zip(mech.design.names, map(float, mech.design.p0)))
        p0 = np.array([initial[name] for name in shown.design.names])
        designs = [("initial", p0), ("optimised", np.asarray(shown.design.p0))]
        write_page(shown, designs, out / VIEW_FILE, None)
    except (LinkoptError, ImportError, KeyError):
        (out / VIEW_FILE).unlink(missing_ok=True)
        return False
    return True


def _initial(job: run_folder.RunFigures) -> None:
    """The file's design's space plot (``spaces_initial.png``), with the job's
    evaluation of that design, else evaluated here."""
    if has_space_plots(job.mech):
        with one_blas_thread():
            _space_plot(job, job.evaluation, None, "initial design")


def _motions(job: run_folder.RunFigures) -> tuple:
    """The motions of both designs (given the optimised design, ``job.optimized``),
    solved, and their GIFs left to draw (:func:`.animation.run_motion_drawings`): with
    workers, the run's side process solves them while the main one draws
    :func:`_optimized`'s figures, then each process draws one GIF
    (:func:`linkopt._design.run.write_outputs`)."""
    from .animation import run_motion_drawings

    with writing("motion_initial.gif, motion_optimized.gif"):
        return run_motion_drawings(job.mech, job.current, job.out, job.optimized)


def _optimized(job: run_folder.RunFigures) -> None:
    """The optimised design's space plot, the convergence and the mechanism figures.
    The space plot solves with the file's mechanism: the rounds' targets, which the
    figure does not use, are part of the fingerprint that keys every compiled program,
    so it shares the file's design's programs."""
    from .plots import plot_convergence, plot_mechanism

    current = job.current
    with one_blas_thread():
        if has_space_plots(current):
            _space_plot(job, job.evaluation, job.design, "optimised design")
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


def _space_plot(job: run_folder.RunFigures, evaluation, design, label: str) -> None:
    """``spaces_optimized.png`` (``design``, with its ``evaluation``) or
    ``spaces_initial.png`` (``design`` None: the file's, evaluated here when
    ``evaluation`` is None)."""
    from .._design.evaluation import evaluate_in_batch
    from .space_plots import plot_spaces

    name = "spaces_initial.png" if design is None else "spaces_optimized.png"
    with writing(name):
        if evaluation is None:
            evaluation = evaluate_in_batch(job.mech, None, job.rows)
        plot_spaces(
            job.mech,
            evaluation,
            job.out / name,
            resolution=job.resolution,
            design=design,
            title=f"{job.mech.name if design is None else job.current.name}, {label}",
            progress=_prefixed(job.progress, f"{label}, "),
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

    With ``workers`` > 1 a side process solves the motions while this one verifies
    both designs and draws the rest, then each draws one motion GIF. ``out`` is
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
