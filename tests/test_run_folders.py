"""Run folders shared by several processes: one holder at a time (a second process is
refused, naming the holder), atomic writes under unique names, no partial results after
a failure, and bad ``--out`` folders or ``--resume`` checkpoints refused with one line
before any optimisation or solve starts."""

import dataclasses
import json
import math
import os
import random
import signal
import socket
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest
from arm_tasks import TINY_ARM
from conftest import MECHANISMS, ROOT, TINY_OPTIMIZE

import linkopt
from linkopt import InputError
from linkopt._arms.codesign import multistart, nlp
from linkopt._cli.main import main
from linkopt._design.optimizer import OptimizerSettings, start
from linkopt._design.run import CHECKPOINT
from linkopt._draw.run_folder import write_outputs
from linkopt._folders import LOCK, STAGING_PREFIX, locked, staged, write_atomic

FIVE_BAR = str(MECHANISMS / "five_bar.toml")
HOLDER = (
    "import sys\n"
    "from linkopt._folders import run_folder\n"
    "with run_folder(sys.argv[1]):\n"
    "    print('locked', flush=True)\n"
    "    sys.stdin.read()\n"
)


def _no_work(*_, **__):
    raise AssertionError("work started although the input was bad")


def _one_error_line(capsys) -> str:
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("linkopt: error: "), err
    return err.strip()


def _optimize(out, *flags) -> int:
    return main(["optimize", FIVE_BAR, "--out", str(out), *TINY_OPTIMIZE, *flags])


def test_a_second_process_is_refused_naming_the_holder_until_it_ends(
    tmp_path, five_bar, capsys
):
    """A real second process holds the folder: ``optimize`` (CLI and library) and an
    arm command exit 2 / raise, naming it; once it is killed the folder is free."""
    folder = tmp_path / "shared"
    holder = subprocess.Popen(
        [sys.executable, "-c", HOLDER, str(folder)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
        cwd=ROOT,
    )
    try:
        assert holder.stdout.readline() == "locked\n"
        who = f"pid {holder.pid} on {socket.gethostname()}"
        assert _optimize(folder) == 2
        err = _one_error_line(capsys)
        assert f"{folder}: in use by another linkopt process ({who})" in err
        points = tmp_path / "points.csv"
        points.write_text("0.5, 0.2, 0.1\n")
        command = ["arm", "manipulability", str(points), "--out", str(folder)]
        assert main(command) == 2 and who in _one_error_line(capsys)
        with pytest.raises(InputError, match=f"in use .*{who}"):
            linkopt.optimize(five_bar, folder, OptimizerSettings(particles=2))
        assert list(folder.iterdir()) == [folder / LOCK]  # nothing written
    finally:
        holder.send_signal(signal.SIGKILL)  # the kernel drops its lock
        holder.wait()
    with locked(folder):
        assert (folder / LOCK).read_text().startswith(f"pid {os.getpid()} ")
    assert not (folder / LOCK).exists()


def test_the_lock_is_reentrant_in_one_process_and_removes_leftovers(tmp_path):
    """Nested holds of one folder (the CLI around the library) share the lock; taking
    it removes a staging folder a killed process left."""
    left = tmp_path / f"{STAGING_PREFIX}killed"
    left.mkdir()
    (left / "design.toml").write_text("half")
    with locked(tmp_path), locked(tmp_path / ".." / tmp_path.name):
        assert (tmp_path / LOCK).exists() and not left.exists()
    assert list(tmp_path.iterdir()) == []


def test_atomic_writes_use_unique_temporary_names(tmp_path):
    """Writers of one file never share a temporary file (the fixed ``.tmp`` name made
    one of two runs die renaming it), and leave none behind."""
    path = tmp_path / CHECKPOINT
    errors = []

    def write(k):
        try:
            for _ in range(100):
                write_atomic(path, f"writer {k}\n")
        except Exception as err:  # noqa: BLE001 - reported below
            errors.append(err)

    threads = [threading.Thread(target=write, args=(k,)) for k in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert errors == [] and [p.name for p in tmp_path.iterdir()] == [CHECKPOINT]
    assert path.read_text() in {f"writer {k}\n" for k in range(4)}
    umask = os.umask(0)
    os.umask(umask)
    assert path.stat().st_mode & 0o777 == 0o666 & ~umask


@pytest.mark.parametrize("durable", [True, False])
def test_an_atomic_write_syncs_only_when_durable(tmp_path, monkeypatch, durable):
    """A checkpoint survives a power cut (fsync before the rename); a cache entry,
    computed again when lost, skips the fsync."""
    synced = []
    monkeypatch.setattr(os, "fsync", synced.append)
    write_atomic(tmp_path / "a.csv", b"1,2\n", durable=durable)
    assert len(synced) == int(durable) and (tmp_path / "a.csv").read_bytes() == b"1,2\n"


def test_staged_results_appear_together_or_not_at_all(tmp_path):
    (tmp_path / "summary.json").write_text("old")
    (tmp_path / "design.toml").write_text("old")
    with pytest.raises(RuntimeError), staged(tmp_path, "summary.json") as stage:
        (stage / "design.toml").write_text("new")
        raise RuntimeError("crash after the first file")
    assert sorted(p.read_text() for p in tmp_path.iterdir()) == ["old", "old"]
    (tmp_path / "arm.toml").write_text("stale")
    with staged(tmp_path, "summary.json", obsolete=["arm.toml"]) as stage:
        (stage / "design.toml").write_text("new")
        (stage / "summary.json").write_text("new")
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == {
        "summary.json": "new",
        "design.toml": "new",
    }


def test_a_crashing_arm_design_leaves_no_result(tmp_path, monkeypatch):
    """``arm design`` crashes after writing ``design.toml`` and the tables: the folder
    is left without any of its files (the solve is faked, the writing is real)."""
    task = tmp_path / "tiny.toml"
    task.write_text(TINY_ARM + "[[targets]]\nposition = [0.3, 0.0, 0.3]\n")

    def fake_solve(problem, **_):
        arm, n = problem.arm, problem.num_waypoints
        solution = multistart.ArmSolution(
            theta=np.zeros((n, arm.num_joints)),
            design=(arm.lower + arm.upper) / 2,
            objective=1.0,
            parts={},
            max_violation=0.0,
            feasible=True,
            iterations=1,
            seconds=0.0,
            message="faked",
            start=0,
        )
        return solution, [solution]

    def fake_report(problem, z):
        n, joints = problem.num_waypoints, problem.arm.num_joints
        return {
            "tip": np.zeros((n, 3)),
            "axis": np.zeros((n, 3)),
            "torque": np.zeros((n, joints)),
        }

    def crash(problem, z):
        staged_files = {p.name for p in out.glob(f"{STAGING_PREFIX}*/*")}
        assert {"design.toml", "waypoints.csv"} <= staged_files  # partial work done
        raise RuntimeError("simulated crash")

    out = tmp_path / "run"
    monkeypatch.setattr(multistart, "solve", fake_solve)
    monkeypatch.setattr(nlp, "waypoint_report", fake_report)
    monkeypatch.setattr(nlp, "evaluate", crash)
    assert main(["arm", "design", str(task), "--out", str(out)]) == 3  # internal error
    assert list(out.iterdir()) == []


def test_a_failing_write_outputs_leaves_the_earlier_outputs(
    tmp_path, five_bar, monkeypatch
):
    """The optimised file is written, then the verification fails: the folder keeps
    its earlier ``optimized.toml`` and ``summary.json``, and gets no part of the new."""
    settings = OptimizerSettings(particles=2, iterations=1)
    record = dict.fromkeys(
        ["iteration", "best_total", "best_f_design", "regularizer", "reach"], 0.0
    )
    run = dataclasses.replace(
        start(five_bar, settings),
        iteration=1,
        finished=True,
        result_pos=five_bar.design.p0,
        history=({**record, "singularity": 0.0, "evaluations": 2, "wall_time": 0},),
    )
    for name in ("optimized.toml", "summary.json"):
        (tmp_path / name).write_text("earlier run")

    def crash(mech, current, stage, *_):
        assert (stage / "optimized.toml").is_file()
        raise RuntimeError("verification failed")

    monkeypatch.setattr("linkopt._design.run._design_outputs", crash)
    with pytest.raises(RuntimeError, match="verification failed"):
        write_outputs(five_bar, tmp_path, run, settings)
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == {
        "optimized.toml": "earlier run",
        "summary.json": "earlier run",
    }


def test_the_run_folder_asks_the_drawing_layer_once_per_design(
    tmp_path, five_bar, monkeypatch
):
    """The design layer draws nothing itself: ``write_outputs`` hands the numbers to
    its ``figures`` in three calls (the file's design's own figures, unevaluated; both
    designs' motions, with the optimised design; the optimised design's figures, with
    its evaluation and the history), and with ``figures=None`` the folder gets no
    figure. (Verification is stood in for: not this test's subject.)"""
    from linkopt._design import run as run_folder

    settings = OptimizerSettings(particles=2, iterations=1)
    record = dict.fromkeys(
        ["iteration", "best_total", "best_f_design", "regularizer", "reach"], 0.0
    )
    design = five_bar.design.p0 + 0.1 * (five_bar.design.upper - five_bar.design.p0)
    run = dataclasses.replace(
        start(five_bar, settings),
        iteration=1,
        finished=True,
        result_pos=design,
        history=({**record, "singularity": 0.0, "evaluations": 2, "wall_time": 0},),
    )
    monkeypatch.setattr(run_folder, "_verification", lambda *_: {"passed": True})
    calls = []
    run_folder.write_outputs(
        five_bar, tmp_path / "a", run, settings, figures=calls.append
    )
    assert len(calls) == 3
    (optimised,) = [job for job in calls if job.design is not None]
    (motions,) = [job for job in calls if job.optimized is not None]
    (initial,) = [job for job in calls if job.design is job.optimized is None]
    np.testing.assert_array_equal(motions.optimized, design)
    assert motions.design is None and motions.mech is five_bar
    assert initial.evaluation is None and initial.mech is five_bar
    np.testing.assert_array_equal(optimised.design, design)
    assert optimised.history == run.history and optimised.mech is five_bar
    assert float(optimised.evaluation.f_design) == pytest.approx(
        float(linkopt.evaluate(five_bar, design).f_design), rel=1e-9, abs=1e-30
    )
    assert initial.rows == motions.rows == optimised.rows > 0
    run_folder.write_outputs(five_bar, tmp_path / "b", run, settings, figures=None)
    written = {p.suffix for p in (tmp_path / "b").iterdir()}
    assert ".png" not in written and ".gif" not in written
    assert (tmp_path / "b" / "summary.json").is_file()


def _spoil(data: dict, case: str):
    """The checkpoint ``data`` spoilt as ``case`` says: (contents, field named)."""
    rng_state = {"bit_generator": "PCG64", "state": "garbage"}
    shrunk = {**data, "position": data["position"][:1]}
    missing = {k: v for k, v in data.items() if k != "velocity"}
    nan = json.loads(json.dumps(data))
    nan["position"][0][1] = math.nan
    return {
        "random bytes": (bytes(random.Random(0).randrange(256) for _ in range(64)), ""),
        "truncated": (json.dumps(data)[:100], ""),
        "{}": ("{}", "mechanism"),
        "a list": ("[1, 2]", "a JSON object"),
        "missing keys": (missing, "velocity"),
        "wrong shapes": (shrunk, "position: expected a 2x3 array"),
        "garbage rng state": ({**data, "rng_state": rng_state}, "rng_state"),
        "nan positions": (nan, "position: expected a 2x3 array of finite numbers"),
        "history too short": ({**data, "iteration": 1}, "history"),
        "iteration a string": ({**data, "iteration": "0"}, "iteration"),
    }[case]


@pytest.mark.parametrize(
    "case",
    [
        "random bytes",
        "truncated",
        "{}",
        "a list",
        "missing keys",
        "wrong shapes",
        "garbage rng state",
        "nan positions",
        "history too short",
        "iteration a string",
        "a folder",
    ],
)
def test_a_corrupt_checkpoint_is_refused_before_any_work(
    case, fresh_checkpoint, monkeypatch, capsys
):
    out, data = fresh_checkpoint
    path = out / CHECKPOINT
    if case == "a folder":
        path.unlink()
        path.mkdir()
        field = "found a directory"
    else:
        contents, field = _spoil(data, case)
        if isinstance(contents, dict):
            contents = json.dumps(contents, allow_nan=True)
        if isinstance(contents, str):
            contents = contents.encode()
        path.write_bytes(contents)
    monkeypatch.setattr("linkopt._design.run.Workers", _no_work)
    assert _optimize(out, "--resume") == 2
    err = _one_error_line(capsys)
    assert f"{path}: " in err and field in err and "expected" in err, err


def test_a_fresh_checkpoint_passes_the_checks(fresh_checkpoint, five_bar):
    """The fixture's checkpoint is valid: the checks refuse only what is spoilt."""
    from linkopt._design.run import load_checkpoint

    out, _ = fresh_checkpoint
    run = load_checkpoint(out, five_bar, OptimizerSettings(particles=2, iterations=1))
    assert run.iteration == 0 and run.position.shape == (2, five_bar.design.size)


def _bad_outs(tmp_path: Path) -> dict:
    taken = tmp_path / "taken"
    taken.write_text("a file, not a directory")
    return {
        "an existing file": (taken, "a file of that name exists"),
        "inside a file": (taken / "run", f"{str(taken)!r} is a file"),
        "uncreatable": (Path("/proc/linkopt-no-such/run"), "No such file"),
        "unwritable": (Path("/proc"), "cannot write to the output directory"),
    }


@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs Linux's /proc")
@pytest.mark.parametrize("command", ["optimize", "plot"])
@pytest.mark.parametrize(
    "case", ["an existing file", "inside a file", "uncreatable", "unwritable"]
)
def test_a_bad_out_is_refused_before_any_work(
    command, case, tmp_path, monkeypatch, capsys
):
    out, words = _bad_outs(tmp_path)[case]
    monkeypatch.setattr("linkopt._design.run.Workers", _no_work)
    monkeypatch.setattr("linkopt._cli.evaluation.evaluate", _no_work)
    extra = TINY_OPTIMIZE if command == "optimize" else ["--resolution", "8"]
    assert main([command, FIVE_BAR, "--out", str(out), *extra]) == 2
    err = _one_error_line(capsys)
    assert "--out: " in err and str(out) in err and words in err, err
    assert "expected a" in err, err


def test_resume_of_an_out_that_is_a_file_names_it(tmp_path, capsys):
    taken = tmp_path / "taken"
    taken.write_text("a file")
    assert _optimize(taken / "run", "--resume") == 2
    assert f"{str(taken)!r} is a file" in _one_error_line(capsys)
    assert _optimize(tmp_path / "none", "--resume") == 2
    assert "no checkpoint to resume" in _one_error_line(capsys)
    assert not (tmp_path / "none").exists()
