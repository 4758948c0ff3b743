"""``linkopt arm manipulability POINTS``: the command writes the DH table, its engine
measures and a mechanism file; bad input exits 2 with one ``linkopt: error:`` line."""

import json

import numpy as np
import pytest
from test_dh_synthesis import SMALL, TASK

import linkopt
from linkopt._arms.dh import synthesis as syn
from linkopt._cli.main import main


@pytest.fixture(scope="module")
def small_synthesis():
    return syn.synthesize_config("RRR", TASK, SMALL)


def test_cli_reports_engine_measures_and_writes_a_mechanism_file(
    tmp_path, small_synthesis
):
    """The command (same task and settings as ``small_synthesis``) writes the table; its
    residuals and w, measured on the engine, equal the closed form; arm.toml's FK
    reaches."""
    points = tmp_path / "task.txt"
    points.write_text(
        "# x y z\n"
        + "\n".join(" ".join(repr(float(v)) for v in p) for p in TASK)
        + "\n"
    )
    out = tmp_path / "out"
    args = [
        "--joints",
        "RRR",
        "--out",
        str(out),
        "--starts",
        "2",
        "--seed",
        "1",
        "--iterations",
        "300",
    ]
    assert main(["arm", "manipulability", str(points), *args]) == 0
    data = json.loads((out / "dh.json").read_text())
    assert data["joints"] == "RRR" and data["theta"] == [None] * 3
    np.testing.assert_allclose(
        [t["q"] for t in data["targets"]], small_synthesis.q, atol=1e-9
    )
    np.testing.assert_allclose(
        [t["residual"] for t in data["targets"]], small_synthesis.residual, atol=1e-9
    )
    np.testing.assert_allclose(
        [t["manipulability"] for t in data["targets"]],
        small_synthesis.manipulability,
        rtol=1e-8,
    )
    assert data["summary"]["reached"] == len(TASK)
    mech = linkopt.load(out / "arm.toml")
    target = data["targets"][2]
    motors = np.array(target["q"]) - np.array(data["rest_q"])
    tip = linkopt.point_positions(mech, linkopt.solve_fk(mech, motors).state)[0]
    np.testing.assert_allclose(tip, target["point"], atol=1e-3)
    assert (out / "manipulability.png").stat().st_size > 10_000


def test_manipulability_bad_input_exits_2_with_one_line(tmp_path, capsys):
    points = tmp_path / "points.csv"
    points.write_text("1, 0, 0\n")
    assert (
        main(
            [
                "arm",
                "manipulability",
                str(points),
                "--joints",
                "RXR",
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 2
    )
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("linkopt: error: --joints:") and "'R'" in err[-1]
    assert (
        main(
            [
                "arm",
                "manipulability",
                str(tmp_path / "missing.csv"),
                "--out",
                str(tmp_path / "o"),
            ]
        )
        == 2
    )
    assert "missing.csv: cannot read" in capsys.readouterr().err


@pytest.mark.parametrize(
    "extra, words",
    [
        (
            ["--precision", "0"],
            "--precision: expected a finite positive number, got 0.0",
        ),
        (["--precision", "nan"], "--precision: expected a finite positive number"),
        (["--precision", "1e300"], "--precision: 1e+300 exceeds the limit of 1e+12"),
        (["--size-damping", "-1"], "--size-damping: expected a finite non-negative"),
        (["--starts", "1000000"], "--starts: 1000000 exceeds the limit of 1000"),
        (["--iterations", "0"], "--iterations: expected a positive integer, got 0"),
        (["--joints", "0"], "--joints: expected a number of joints between 1 and 8"),
        (
            ["--joints", "R" * 13],
            "--joints: 'RRRRRRRRRRRRR': 13 joints exceed the limit",
        ),
    ],
)
def test_manipulability_flags_are_checked_before_work(extra, words, tmp_path, capsys):
    argv = ["arm", "manipulability", str(tmp_path / "never_read.csv")]
    assert main([*argv, "--out", str(tmp_path / "o"), *extra]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"linkopt: error: {words}") and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "text, words",
    [
        ("1, 0, 0\n1e200, 0, 0\n", "line 2: expected coordinates of magnitude at most"),
        ("1, 0, nan\n", "line 1: expected 3 finite numbers"),
        ("x,y,z\n" + "0.1, 0.2, 0.3\n" * 10_001, "more than 10000 task points"),
    ],
)
def test_points_file_with_absurd_content_exits_2(text, words, tmp_path, capsys):
    points = tmp_path / "points.csv"
    points.write_text(text)
    assert (
        main(["arm", "manipulability", str(points), "--out", str(tmp_path / "o")]) == 2
    )
    err = capsys.readouterr().err
    assert err.startswith(f"linkopt: error: {points}: ") and words in err
    assert err.count("\n") == 1
