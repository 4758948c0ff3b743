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
