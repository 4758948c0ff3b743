"""``linkopt synthesize`` (issue 41): the run folder, the summary, bad flags."""

from __future__ import annotations

import csv
import json

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._cli.main import main
from linkopt.synthesis import load_targets

FILE = MECHANISMS / "four_bar_path.toml"


@pytest.mark.parametrize(
    ("flags", "words"),
    [
        (["--steps", "3"], "--steps: expected 8"),
        (["--particles", "0"], "--particles: expected a positive integer"),
        ([], "--out: a synthesis run needs its run folder"),
    ],
)
def test_bad_flags_are_refused_with_one_line(flags, words, capsys):
    assert main(["synthesize", str(FILE), *flags]) == 2
    err = capsys.readouterr().err
    assert words in err and err.count("\n") == 1


def test_a_file_without_a_synthesis_table_is_refused(tmp_path, capsys):
    out = tmp_path / "run"
    assert (
        main(["synthesize", str(MECHANISMS / "four_bar.toml"), "--out", str(out)]) == 2
    )
    assert "[synthesis]: missing table" in capsys.readouterr().err


def test_the_run_folder_holds_the_design_history_summary_and_figure(tmp_path, capsys):
    out = tmp_path / "run"
    flags = ["--particles", "4", "--iterations", "2", "--steps", "72", "--seed", "1"]
    assert main(["synthesize", str(FILE), "--out", str(out), *flags]) == 0
    printed = json.loads(capsys.readouterr().out)
    summary = json.loads((out / "summary.json").read_text())
    assert printed == summary
    for key in ("rms", "max_distance", "cycle_solved", "least_sigma_fk", "verified"):
        assert key in summary
    distances = np.asarray(summary["distances"])
    assert summary["rms"] == pytest.approx(np.sqrt(np.mean(distances**2)))
    assert summary["max_distance"] == pytest.approx(distances.max())
    assert summary["rms"] <= summary["initial_rms"]
    with open(out / "history.csv") as handle:
        rows = list(csv.DictReader(handle))
    assert len(rows) == summary["iterations"] <= 2
    assert (out / "synthesis.png").stat().st_size > 0
    page = (out / "view.html").read_text()  # the browser view: targets, traced curve
    assert '"curve":{"kind":"path","name":"coupler_point"' in page
    written = linkopt.load(out / "optimized.toml")
    np.testing.assert_allclose(written.design.p0, summary["design"], rtol=1e-12)
    targets = load_targets(written)  # the [synthesis] table travels with the design
    np.testing.assert_array_equal(
        targets.values, load_targets(linkopt.load(FILE)).values
    )
    assert summary["verified"] in (True, False)
    assert summary["four_bar"]["grashof"] in ("crank-rocker", "double-crank")
    code = main(
        ["synthesize", str(FILE), "--verify", "--steps", "72", "--design",
         str(out / "optimized.toml")]
    )  # fmt: skip
    report = json.loads(capsys.readouterr().out)
    assert code == (0 if report["verified"] else 1)
