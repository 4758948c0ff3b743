"""A run folder's final outputs made by two processes (issue 43): the file's design's
figures (both designs' motions) in a side process while this one verifies both
designs and draws the optimised design's (both space plots among them). The files are
those of the serial outputs; an error in an output is raised here naming that
output, from whichever process; and the side process is one of the optimiser's,
handed back warm where the command line asks for it (:mod:`linkopt._design.ahead`)."""

import dataclasses
import io
import os
from functools import partial

import numpy as np
import pytest

from linkopt._design import ahead
from linkopt._design import run as run_folder
from linkopt._design.evaluation import evaluate_in_batch
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


@pytest.fixture(scope="module")
def serial(tmp_path_factory, five_bar):
    """The files of :func:`_finished_run`'s outputs made by this process alone
    (``workers=1``) and their progress stages, made once for the tests that compare
    other ways of making them with these."""
    folder, records = tmp_path_factory.mktemp("serial") / "run", []
    run_folder.write_outputs(
        five_bar,
        folder,
        _finished_run(five_bar),
        SETTINGS,
        figures=draw_run_figures,
        workers=1,
        progress=records.append,
    )
    return _files(folder), {r["stage"].split(",")[0] for r in records}


def test_the_outputs_of_two_processes_are_the_serial_ones(tmp_path, five_bar, serial):
    """``workers=2`` (the side process draws both designs' motions), at the default
    resolutions (shared with the other run-folder tests' programs), writes the same
    files as ``workers=1`` (all here): the same verification numbers, summary,
    optimised file and MJCF, the same GIF and PNG bytes (the space maps to a few
    pixels: :data:`MAPS`); and every figure of a run folder is there."""
    run_folder.write_outputs(
        five_bar,
        tmp_path / "w2",
        _finished_run(five_bar),
        SETTINGS,
        figures=draw_run_figures,
        workers=2,
    )
    serial, parallel = serial[0], _files(tmp_path / "w2")
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


def _held_with_initial(mech, rows: int, figures, resolution=None) -> None:
    """As ``linkopt optimize`` does: processes spawned ahead, the file's design's
    figures asked for ahead (:func:`ahead.early`), and a finished ``Workers`` that
    hands its process back, which then starts them."""
    ahead.start(2)
    ahead.early(run_folder.initial_figures, mech, rows, resolution, figures)
    with Workers(mech, 2):
        pass


def test_the_file_designs_outputs_made_ahead_are_those_made_here(
    tmp_path, five_bar, serial
):
    """The file's design's space plot, drawn ahead by the process the optimiser
    handed back (:func:`run_folder.initial_figures`), is taken by ``write_outputs``
    (which then does not map that design itself: no such progress record) and gives
    the files one process makes alone. Drawn ahead with other arguments (another
    resolution), it is not taken: drawn here."""
    run = _finished_run(five_bar)
    rows = run_folder.swarm_rows(len(run.position), 2)
    folders, stages = {}, {"serial": serial[1]}
    for name in ("ahead", "other"):
        folders[name], records = tmp_path / name, []
        try:
            resolution = None if name == "ahead" else 8
            _held_with_initial(five_bar, rows, draw_run_figures, resolution)
            run_folder.write_outputs(
                five_bar,
                folders[name],
                run,
                SETTINGS,
                figures=draw_run_figures,
                workers=2,
                progress=records.append,
            )
            assert ahead.early_result() is None  # taken by write_outputs
        finally:
            ahead.close()
        stages[name] = {r["stage"].split(",")[0] for r in records}
    assert "initial design" in stages["serial"] and "initial design" in stages["other"]
    assert "initial design" not in stages["ahead"]
    assert "optimised design" in stages["ahead"]
    serial, made_ahead = serial[0], _files(folders["ahead"])
    assert serial.keys() == made_ahead.keys() == _files(folders["other"]).keys()
    for name in serial.keys() - MAPS:
        assert serial[name] == made_ahead[name], name
    for name in MAPS:
        a, b = (_pixels(files[name]) for files in (serial, made_ahead))
        assert a.shape == b.shape and np.mean(np.any(a != b, axis=-1)) < 1e-3, name


def _fail_initial(job) -> None:  # module level: it runs in the process held ahead
    if job.design is None and job.optimized is None:
        with writing("spaces_initial.png"):
            raise ValueError("no cells to draw")


def test_an_error_in_the_outputs_made_ahead_names_the_output(
    tmp_path, five_bar, monkeypatch
):
    """A figure of the file's design that fails in the process that made it ahead is
    raised by ``write_outputs`` as :class:`OutputError` naming it, and the folder gets
    none of the outputs. (The optimised design's verification is stood in for.)"""
    monkeypatch.setattr(run_folder, "_verification", lambda *_: {"passed": True})
    run = _finished_run(five_bar)
    try:
        _held_with_initial(
            five_bar, run_folder.swarm_rows(len(run.position), 2), _fail_initial
        )
        with pytest.raises(OutputError) as raised:
            run_folder.write_outputs(
                five_bar, tmp_path, run, SETTINGS, figures=_fail_initial, workers=2
            )
    finally:
        ahead.close()
    assert str(raised.value) == "spaces_initial.png: ValueError: no cells to draw"
    assert list(tmp_path.iterdir()) == []


def test_the_view_drawn_beside_the_figures_is_the_command_lines(tmp_path, five_bar):
    """``draw_run_figures_and_view`` (what ``linkopt optimize`` passes) writes the run
    folder's ``view.html`` with the motions, the same bytes as the page
    ``linkopt view DIR`` writes from the finished folder
    (:func:`linkopt._cli.view.write_run_view`); a folder without ``optimized.toml``
    gets none, and False says so (the command line then writes it or warns)."""
    from linkopt._cli.view import write_run_view
    from linkopt._draw.run_folder import VIEW_FILE, draw_run_figures_and_view, run_view

    out = tmp_path / "run"
    run_folder.write_outputs(
        five_bar,
        out,
        _finished_run(five_bar),
        SETTINGS,
        figures=draw_run_figures_and_view,
        workers=1,
    )
    drawn = (out / VIEW_FILE).read_bytes()
    (out / VIEW_FILE).unlink()
    write_run_view(out)
    assert (out / VIEW_FILE).read_bytes() == drawn
    empty = tmp_path / "empty"
    empty.mkdir()
    assert not run_view(five_bar, empty)
    assert list(empty.iterdir()) == []


def _pid_file(path) -> None:  # module level: a drawing left to the side process
    path.write_text(str(os.getpid()))


def _leave_two(job):
    """Figures whose motions job leaves two drawings, each writing its process id."""
    if job.design is None and job.optimized is not None:
        return tuple(partial(_pid_file, job.out / n) for n in ("first", "last"))
    return None


@pytest.mark.parametrize("workers", [1, 2])
def test_the_drawings_a_call_leaves_are_shared_between_the_processes(
    tmp_path, five_bar, monkeypatch, workers
):
    """The drawings the motions' call leaves (the two GIFs) run at once: with a side
    process, all but the last there and the last here; without one, all here. Both
    are written in the run folder either way. (Verification is stood in for.)"""
    monkeypatch.setattr(run_folder, "_verification", lambda *_: {"passed": True})
    run_folder.write_outputs(
        five_bar,
        tmp_path,
        _finished_run(five_bar),
        SETTINGS,
        figures=_leave_two,
        workers=workers,
    )
    pids = {n: int((tmp_path / n).read_text()) for n in ("first", "last")}
    assert pids["last"] == os.getpid()
    assert (pids["first"] != os.getpid()) == (workers == 2)


def _keep_evaluation(job) -> None:  # module level: it runs in the process held ahead
    import pickle

    (job.out / "evaluation.pickle").write_bytes(pickle.dumps(job.evaluation))


def test_the_run_hands_the_file_designs_evaluation_to_the_figures_made_ahead(
    tmp_path, five_bar
):
    """A fresh run gives the file's design's figures made ahead its first iteration's
    evaluation of that design (its first particle), which is, field by field and bit
    for bit, the one those figures would compute themselves."""
    import pickle

    settings = OptimizerSettings(particles=2, iterations=1, verify_rounds=0)
    rows = run_folder.swarm_rows(settings.particles, 2)
    try:
        ahead.start(2)
        ahead.early(run_folder.initial_figures, five_bar, rows, None, _keep_evaluation)
        run_folder.optimize(five_bar, tmp_path / "run", settings, workers=2)
        _, future = ahead.early_result()
        given = pickle.loads(future.result()["evaluation.pickle"])
    finally:
        ahead.close()
    assert given is not None
    own = evaluate_in_batch(five_bar, None, rows)
    for field in dataclasses.fields(own):
        a, b = (np.asarray(getattr(e, field.name)) for e in (given, own))
        nan = np.issubdtype(b.dtype, np.inexact)
        assert a.dtype == b.dtype, field.name
        assert np.array_equal(a, b, equal_nan=nan), field.name
