"""``linkopt fk`` / ``linkopt bk``: one configuration from comma-separated values or a
continuation path from a CSV file; bad values exit 2, a failed solve exits 1."""

import json

import numpy as np
import pytest
from conftest import MECHANISMS

from linkopt._cli.main import main


def test_fk_json_and_bk_round_trip_via_cli(capsys):
    path = str(MECHANISMS / "five_bar.toml")
    assert main(["fk", path, "--motors", "0.2,-0.1", "--json"]) == 0
    fk = json.loads(capsys.readouterr().out)
    for key in (
        "converged",
        "residual",
        "motors",
        "outputs",
        "joints",
        "points",
        "f_sing",
        "sigma_min_fk",
        "sigma_min_bk",
    ):
        assert key in fk
    assert fk["converged"] and fk["residual"] <= 1e-10
    assert fk["f_sing"] == pytest.approx(
        1 / fk["sigma_min_fk"] + 1 / fk["sigma_min_bk"]
    )
    outputs = f"{fk['outputs']['x']!r},{fk['outputs']['y']!r}"
    assert main(["bk", path, "--outputs", outputs, "--json"]) == 0
    bk = json.loads(capsys.readouterr().out)
    assert bk["motors"]["left"] == pytest.approx(0.2, abs=1e-9) and bk["motors"][
        "right"
    ] == pytest.approx(-0.1, abs=1e-9)
    np.testing.assert_allclose(bk["points"]["ee"], fk["points"]["ee"], atol=1e-9)


def test_fk_csv_path_via_cli(tmp_path, capsys):
    csv_path = tmp_path / "motors.csv"
    csv_path.write_text("left,right\n0,0\n0.1,-0.05\n0.2,-0.1\n")
    assert (
        main(
            [
                "fk",
                str(MECHANISMS / "five_bar.toml"),
                "--motors",
                str(csv_path),
                "--json",
            ]
        )
        == 0
    )
    result = json.loads(capsys.readouterr().out)
    assert result["converged"] and len(result["path"]) == 3
    assert result["path"][2]["motors"]["left"] == pytest.approx(0.2)


@pytest.mark.parametrize(
    "args, message",
    [
        (["fk", "--motors", "0.1"], "expected 2 finite numbers (left, right)"),
        (["bk", "--outputs", "a,b"], "expected 2 comma-separated numbers (x, y)"),
    ],
)
def test_bad_values_are_rejected(args, message, capsys):
    assert main([args[0], str(MECHANISMS / "five_bar.toml"), *args[1:]]) == 2
    assert message in capsys.readouterr().err


def test_bad_csv_header_names_file_and_line(tmp_path, capsys):
    csv_path = tmp_path / "m.csv"
    csv_path.write_text("a,b\n0,0\n")
    assert (
        main(["fk", str(MECHANISMS / "five_bar.toml"), "--motors", str(csv_path)]) == 2
    )
    assert f"{csv_path}: line 1: header" in capsys.readouterr().err


def test_negative_values_are_not_taken_for_options(capsys):
    assert (
        main(
            ["fk", str(MECHANISMS / "five_bar.toml"), "--motors", "-0.1,0.1", "--json"]
        )
        == 0
    )
    assert json.loads(capsys.readouterr().out)["motors"]["left"] == pytest.approx(-0.1)


def test_failed_solve_exits_one(capsys):
    assert main(["bk", str(MECHANISMS / "five_bar.toml"), "--outputs", "0,200"]) == 1
    assert "BK solve failed" in capsys.readouterr().err


def test_fk_with_a_large_crank_angle_stays_on_the_rest_branch(capsys):
    """Regression: ``fk jansen_1dof.toml --motors 3.14159265359`` reported
    ``converged: true`` with the foot near (-60, -48), another assembly of the leg; the
    rest branch (reached along a path) puts it at about (-33.7, -73.5)."""
    path = str(MECHANISMS / "jansen_1dof.toml")
    assert main(["fk", path, "--motors", "3.14159265359", "--json"]) == 0
    fk = json.loads(capsys.readouterr().out)
    assert fk["converged"] and fk["progress"] == 1.0
    np.testing.assert_allclose(
        fk["points"]["foot"][:2], [-33.7297, -73.5171], atol=1e-3
    )


def test_fk_past_the_reach_names_where_the_branch_stops(capsys):
    """Pulling the five-bar's cranks apart stretches the distal links out before the
    requested motors: exit 1, naming the motor values where the branch ends."""
    path = str(MECHANISMS / "five_bar.toml")
    assert main(["fk", path, "--motors", "0.9,-0.9", "--json"]) == 1
    captured = capsys.readouterr()
    fk = json.loads(captured.out)
    assert not fk["converged"] and 0.0 < fk["progress"] < 1.0
    left = fk["motors"]["left"]
    assert left == pytest.approx(0.9 * fk["progress"], abs=1e-6)
    error = captured.err.strip()
    assert error.count("\n") == 0 and "FK solve failed" in error
    assert f"left={left:.6g}" in error and "% of the way from the rest pose" in error


def test_a_failed_fk_reports_the_state_it_prints_not_the_solver_residual(capsys):
    """Regression: past a fold ``fk`` printed ``converged=False residual=5.43e-02``
    (the miss of the motor targets) beside a state that closes to 1e-12. It now gives
    the loop closure of the printed state and how far its motors are from those
    asked."""
    path = str(MECHANISMS / "five_bar.toml")
    assert main(["fk", path, "--motors", "0.9,-0.9", "--json"]) == 1
    fk = json.loads(capsys.readouterr().out)
    assert fk["closure"] <= 1e-10
    reached = np.array([fk["motors"]["left"], fk["motors"]["right"]])
    assert fk["miss"] == pytest.approx(np.max(np.abs(reached - [0.9, -0.9])))
    assert fk["miss"] > 0.1
    assert main(["fk", path, "--motors", "0.9,-0.9"]) == 1
    captured = capsys.readouterr()
    first = captured.out.splitlines()[0]
    assert "converged=False closure=" in first and "motors miss=" in first
    assert "residual" not in first
    assert "closes its loops to" in captured.err
    assert f"miss those asked by up to {fk['miss']:.3g}" in captured.err


def test_a_csv_that_is_not_utf8_exits_2_naming_the_file(tmp_path, capsys):
    """Regression: a binary file given as ``--motors`` raised UnicodeDecodeError."""
    path = tmp_path / "motors.csv"
    path.write_bytes(b"\xff\xfe\x00left,right\n")
    assert main(["fk", str(MECHANISMS / "five_bar.toml"), "--motors", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and f"{path}: not a UTF-8 text file" in err
