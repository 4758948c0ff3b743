"""The run folder of ``linkopt synthesize`` beyond the design and summary: the
animation of the cycle over the targets, the exports, the checkpoint and
``--resume`` (an interrupted run resumed ends exactly where an uninterrupted one
does), the progress lines, and the bad flags and checkpoints refused with one line.
Small swarms and short cycles: a few iterations of the shipped four-bar path."""

from __future__ import annotations

import json
import re
import shutil
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from conftest import MECHANISMS
from PIL import Image

import linkopt
from linkopt._cli import synth_checkpoint
from linkopt._cli.main import main
from linkopt._draw.synthesis import cycle_frames

FILE = MECHANISMS / "four_bar_path.toml"
FLAGS = ["--particles", "4", "--steps", "72", "--seed", "3"]


def _run(out, *extra) -> int:
    return main(["synthesize", str(FILE), "--out", str(out), *FLAGS, *extra])


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("synth") / "run"
    assert _run(out, "--iterations", "3", "--export", "mjcf,svg") == 0
    return out


def test_the_animation_shows_the_cycle_frame_by_frame(folder):
    summary = json.loads((folder / "summary.json").read_text())
    assert summary["animation"] == str(folder / "synthesis.gif")
    with Image.open(folder / "synthesis.gif") as gif:
        assert gif.n_frames == 72  # one frame per row of the 72-row cycle
        first = np.asarray(gif.convert("RGB"))
        gif.seek(36)
        middle = np.asarray(gif.convert("RGB"))
    assert np.mean(np.any(first != middle, axis=2)) > 0.001  # the linkage moved


def test_cycle_frames_are_the_cycle_s_rows_evenly_first_and_last():
    mech = linkopt.load(FILE)
    result = linkopt.synthesis.score(mech, linkopt.synthesis.load_targets(mech))
    rows = cycle_frames(result, 24)
    motors = np.asarray(result.motors)
    assert rows.shape == (24, 1)
    np.testing.assert_array_equal(rows[0], motors[0])
    np.testing.assert_array_equal(rows[-1], motors[-1])
    assert np.all(np.diff(rows[:, 0]) > 0)  # in the cycle's order
    assert len(cycle_frames(result, 10_000)) == len(motors)


def test_the_exports_are_the_synthesised_design(folder):
    summary = json.loads((folder / "summary.json").read_text())
    assert set(summary["exports"]) == {"mjcf", "svg"}
    written = linkopt.load(folder / "optimized.toml")
    root = ET.parse(folder / "optimized.xml").getroot()
    assert root.tag == "mujoco"
    names = {b.get("name") for b in root.iter("body")}
    assert set(written.body_names) - {written.body_names[written.ground]} <= names
    svg = ET.parse(folder / "optimized.svg").getroot()
    assert svg.tag.endswith("svg")
    # the export is of the synthesised design, not the file's: exporting the
    # written file again gives the same drawing
    again = folder.parent / "again.svg"
    assert main(["export", str(folder / "optimized.toml"), "--format", "svg",
                 "--out", str(again)]) == 0  # fmt: skip
    _same_drawing(again.read_text(), (folder / "optimized.svg").read_text())


def _same_drawing(a: str, b: str) -> None:
    """The same SVG text but for the last digits of its numbers: the run draws its
    design vector, the export the file written from it, whose anchors are that
    vector's rounded sums (a difference in the 16th digit)."""
    number = r"-?\d+\.?\d*(?:e[-+]?\d+)?"
    assert re.sub(number, "#", a) == re.sub(number, "#", b)
    values = [np.array(re.findall(number, t), dtype=float) for t in (a, b)]
    np.testing.assert_allclose(values[0], values[1], rtol=1e-12, atol=1e-9)


def test_progress_goes_to_stderr_iteration_by_iteration(tmp_path, capsys):
    assert _run(tmp_path / "run", "--iterations", "2", "--export", "none") == 0
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert sum(line.startswith("iteration ") for line in lines) == 2
    assert any("scoring the file's design" in line for line in lines)
    assert any("writing the synthesised file" in line for line in lines)
    assert json.loads(captured.out)["exports"] == {}


class Interrupted(Exception):
    pass


def test_a_resumed_run_ends_as_an_uninterrupted_one(tmp_path, monkeypatch, capsys):
    whole = tmp_path / "whole"
    assert _run(whole, "--iterations", "4", "--export", "none") == 0
    expected = json.loads((whole / "summary.json").read_text())
    saved = synth_checkpoint.save

    def stop_after_two(out, run, *args):
        saved(out, run, *args)
        if run.iteration == 2:
            raise Interrupted

    monkeypatch.setattr(synth_checkpoint, "save", stop_after_two)
    cut = tmp_path / "cut"
    assert _run(cut, "--iterations", "4", "--export", "none") not in (0, 2)  # cut
    monkeypatch.setattr(synth_checkpoint, "save", saved)
    assert not (cut / "summary.json").exists()
    assert _run(cut, "--iterations", "4", "--export", "none") == 2  # needs --resume
    assert "pass --resume" in capsys.readouterr().err
    assert _run(cut, "--iterations", "4", "--export", "none", "--resume") == 0
    assert "after 2 finished iterations" in capsys.readouterr().err
    resumed = json.loads((cut / "summary.json").read_text())
    assert resumed["design"] == expected["design"]
    assert resumed["iterations"] == expected["iterations"]
    assert resumed["distances"] == expected["distances"]


@pytest.mark.parametrize(
    ("extra", "words"),
    [
        (["--export", "pdf"], "--export: expected formats among"),
        (["--export", "urdf"], "URDF cannot hold closed loops"),
        (["--resume"], "no checkpoint to resume"),
        (["--verify", "--resume"], "--resume: not with --verify"),
    ],
)
def test_bad_export_and_resume_flags_are_one_line(tmp_path, capsys, extra, words):
    assert _run(tmp_path / "run", "--iterations", "1", *extra) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1
    assert "--format" not in err  # a flag of `linkopt export`, not of this command
    assert not (tmp_path / "run" / "checkpoint.json").exists()


@pytest.fixture(scope="module")
def two_iterations(tmp_path_factory):
    """A run folder after two iterations, made once for the tests that copy it."""
    out = tmp_path_factory.mktemp("checkpointed") / "run"
    assert _run(out, "--iterations", "2", "--export", "none") == 0
    return out


def _checkpointed(tmp_path, run):
    """A copy of ``run`` (the run folder of :func:`two_iterations`) in ``tmp_path``
    and its checkpoint."""
    out = tmp_path / "run"
    shutil.copytree(run, out)
    return out, json.loads((out / "checkpoint.json").read_text())


@pytest.mark.parametrize(
    ("edit", "words"),
    [
        (lambda d: d["run"].update(position=[[1.0]]), "run.position: expected shape"),
        (lambda d: d["run"].update(history=[]), "run.history: expected one record"),
        (lambda d: d["run"].update(rng_state="x"), "run.rng_state"),
        (lambda d: d.update(steps=90), "steps: the checkpoint is of another run"),
        (lambda d: d.update(targets="0"), "targets: the checkpoint is of another run"),
        (lambda d: d.pop("run"), "run: expected a checkpoint written by"),
    ],
)
def test_a_bad_checkpoint_is_refused_naming_the_field(
    tmp_path, capsys, two_iterations, edit, words
):
    out, data = _checkpointed(tmp_path, two_iterations)
    edit(data)
    (out / "checkpoint.json").write_text(json.dumps(data))
    capsys.readouterr()
    assert _run(out, "--iterations", "2", "--export", "none", "--resume") == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1 and "checkpoint.json" in err


def test_another_seed_does_not_resume_the_run(tmp_path, capsys, two_iterations):
    out, _ = _checkpointed(tmp_path, two_iterations)
    capsys.readouterr()
    flags = ["--iterations", "2", "--export", "none", "--resume", "--seed", "4"]
    assert main(["synthesize", str(FILE), "--out", str(out), *FLAGS[:4], *flags]) == 2
    assert "settings: the checkpoint is of another run" in capsys.readouterr().err


def test_a_spatial_cycle_is_animated_in_3d_over_its_targets(tmp_path):
    from linkopt._draw.synthesis import animate_synthesis

    mech = linkopt.load(MECHANISMS / "spherical_four_bar.toml")
    targets = linkopt.synthesis.load_targets(mech)
    result = linkopt.synthesis.score(mech, targets, steps=120)
    path = animate_synthesis(mech, result, tmp_path / "cycle.gif", frames=24)
    with Image.open(path) as gif:
        assert gif.n_frames == 24
        gif.seek(12)
        gif.convert("RGB").save(tmp_path / "frame.png")
        frame = np.asarray(gif.convert("RGB")).astype(int)
    red = (frame[..., 0] > 180) & (frame[..., 1] < 90) & (frame[..., 2] < 90)
    assert red.sum() > 12 * 4  # the twelve target dots are drawn
