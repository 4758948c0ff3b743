"""A run folder's final outputs made by two processes (issue 43): the file's design's
figures (both designs' motions) in a side process while this one verifies both
designs and draws the optimised design's (both space plots among them). The files are
those of the serial outputs; an error in an output is raised here naming that
output, from whichever process; and the side process is one of the optimiser's,
handed back warm where the command line asks for it (:mod:`linkopt._design.ahead`)."""

import dataclasses
import io

import numpy as np
import pytest

from linkopt._design import ahead
from linkopt._design import run as run_folder
from linkopt._design.optimizer import OptimizerSettings, start
from linkopt._design.run import OutputError, writing
from linkopt._design.workers import Workers
from linkopt._draw.run_folder import draw_run_figures

SETTINGS = OptimizerSettings(particles=2, iterations=1)


def _finished_run(mech):
    """A one-iteration run of ``mech`` whose design is 10 % towards its upper bounds."""
    record = dict.fromkeys(
        ["iteration", "best_total", "best_f_design", "regularizer", "reach"], 0.0
    )
    design = mech.design.p0 + 0.1 * (mech.design.upper - mech.design.p0)
    return dataclasses.replace(
        start(mech, SETTINGS),
        iteration=1,
        finished=True,
        result_pos=design,
        history=({**record, "singularity": 0.0, "evaluations": 2, "wall_time": 0},),
    )


def _files(folder) -> dict[str, bytes]:
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def _fail_in(name: str):
    """A :data:`~linkopt._design.run.Figures` whose ``name`` output fails (a bug in a
    figure): the file's design's job fails for ``motion_initial.gif``, the optimised
    one's for ``convergence.png``."""
    return {"side": _fail_side, "main": _fail_main}[name]


def _fail_side(job) -> None:  # module level: it runs in the spawned side process
    if job.design is None:
        with writing("motion_initial.gif"):
            raise ValueError("no frames to draw")


def _fail_main(job) -> None:
    if job.design is not None:
        with writing("convergence.png"):
            raise ValueError("no records to plot")


def test_the_outputs_of_two_processes_are_the_serial_ones(tmp_path, five_bar):
    """``workers=2`` (the side process draws both designs' motions), at the default
    resolutions (shared with the other run-folder tests' programs), writes the same
    files as ``workers=1`` (all here): the same verification numbers, summary,
    optimised file and MJCF, the same GIF and PNG bytes (the space maps to a few
    pixels: :data:`MAPS`); and every figure of a run folder is there."""
    run = _finished_run(five_bar)
    folders = {}
    for workers in (1, 2):
        folders[workers] = tmp_path / f"w{workers}"
        run_folder.write_outputs(
            five_bar,
            folders[workers],
            run,
            SETTINGS,
            figures=draw_run_figures,
            workers=workers,
        )
    serial, parallel = _files(folders[1]), _files(folders[2])
    assert {
        "optimized.toml",
        "optimized.xml",
        "summary.json",
        "verification.json",
        "spaces_initial.png",
        "spaces_optimized.png",
        "convergence.png",
        "mechanism.png",
        "motion_initial.gif",
        "motion_optimized.gif",
    } <= set(serial)
    assert serial.keys() == parallel.keys()
    for name in serial.keys() - MAPS:
        assert serial[name] == parallel[name], name
    for name in MAPS:
        a, b = (_pixels(files[name]) for files in (serial, parallel))
        assert a.shape == b.shape and np.mean(np.any(a != b, axis=-1)) < 1e-3, name
    assert serial["motion_initial.gif"] != serial["motion_optimized.gif"]


#: The space maps: the same to a few pixels, not byte for byte. A process's second
#: run-folder map of a mechanism can differ from its first in about 150 of 624,000
#: pixels (main's serial outputs too: two ``write_outputs`` in one process), so the
#: two halves' maps, drawn by processes with other histories, are compared as images.
MAPS = {"spaces_initial.png", "spaces_optimized.png"}


def _pixels(data: bytes) -> np.ndarray:
    from PIL import Image

    return np.asarray(Image.open(io.BytesIO(data)).convert("RGB"))


@pytest.mark.parametrize("where", ["side", "main"])
@pytest.mark.parametrize("workers", [1, 2])
def test_an_error_in_one_output_names_it_and_leaves_no_outputs(
    tmp_path, five_bar, monkeypatch, where, workers
):
    """A figure that fails, in the side process (``workers=2``) or here, is raised as
    :class:`OutputError` naming that figure and what failed; the folder gets none of
    the outputs (they are staged). (Verification is stood in for: not the subject.)"""
    monkeypatch.setattr(run_folder, "_verification", lambda *_: {"passed": True})
    name, failure = {
        "side": ("motion_initial.gif", "ValueError: no frames to draw"),
        "main": ("convergence.png", "ValueError: no records to plot"),
    }[where]
    with pytest.raises(OutputError) as raised:
        run_folder.write_outputs(
            five_bar,
            tmp_path,
            _finished_run(five_bar),
            SETTINGS,
            figures=_fail_in(where),
            workers=workers,
        )
    assert str(raised.value) == f"{name}: {failure}"
    assert list(tmp_path.iterdir()) == []


def test_writing_names_the_output_and_keeps_the_cause():
    """:func:`writing` wraps a bug's exception as one line naming the output, with the
    original as its cause; a :class:`~linkopt.LinkoptError` (which names its file
    already) passes unchanged."""
    from linkopt import InputError

    with pytest.raises(OutputError, match=r"^view\.html: KeyError: 'x'$") as raised:
        with writing("view.html"):
            {}["x"]
    assert isinstance(raised.value.__cause__, KeyError)
    with pytest.raises(InputError, match="^f.toml: bad$"):
        with writing("view.html"):
            raise InputError("f.toml: bad")


def _imported(name: str) -> bool:  # module level: it runs in a worker process
    import sys

    return name in sys.modules


def test_the_optimisers_processes_serve_the_outputs_only_where_asked(five_bar):
    """After :func:`ahead.start` (the command line), a finished ``Workers`` hands its
    process back: the next ``Workers`` of as many adopts it, or the outputs take it
    (:func:`ahead.side`), importing the modules :func:`ahead.start` named as ``warm``
    once held, and :func:`ahead.close` ends what is held. Without
    :func:`ahead.start` (the library), nothing is held after a ``Workers``."""
    with Workers(five_bar, 2) as workers:
        pool = workers._pool
    assert ahead.side() is None  # the library's Workers ends its processes
    assert pool._shutdown_thread
    try:
        ahead.start(2, warm=("wave",))
        with Workers(five_bar, 2) as workers:
            first = workers._pool
            assert not first.submit(_imported, "wave").result()
        with Workers(five_bar, 2) as workers:
            assert workers._pool is first  # adopted by the next round's Workers
        side = ahead.side()
        assert side is first and ahead.side() is None
        # alive, and warm: the module asked for imported once it was held
        assert side.submit(_imported, "wave").result()
        assert ahead.keep(2, side)
    finally:
        ahead.close()
    assert ahead.side() is None and side._shutdown_thread
