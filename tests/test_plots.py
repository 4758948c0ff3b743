"""Continuation maps against the five-bar closed form, and the plot/evaluate
commands."""

import json

import matplotlib.image as mpimg
import numpy as np
from conftest import MECHANISMS
from five_bar_closed_form import L2, elbows, forward
from scipy import ndimage

import linkopt
from linkopt._cli import main as cli
from linkopt._design.maps import motor_map


def test_motor_map_matches_closed_form_feasibility(five_bar):
    grid = motor_map(
        five_bar,
        [-1.5, -1.5],
        [1.5, 1.5],
        25,
        start_state=linkopt.rest_state(five_bar),
        start_motors=[0.0, 0.0],
    )
    motors = np.stack(np.meshgrid(grid.axis0, grid.axis1, indexing="ij"), -1)
    e_l, e_r = elbows(motors.reshape(-1, 2))
    gap = np.linalg.norm(e_r - e_l, axis=1).reshape(25, 25)
    labels, _ = ndimage.label(gap < 2 * L2)
    expected = labels == labels[12, 12]  # the component of the rest pose
    # cells away from both forward-singular sets: distal links aligned (gap = 2 L2) and
    # elbows coincident (gap = 0, where the tip is undetermined)
    clear = (np.abs(gap - 2 * L2) > 2.0) & (gap > 10.0)
    assert expected.sum() > 100 and (~expected).sum() > 50
    np.testing.assert_array_equal(grid.feasible[clear], expected[clear])
    tips = grid.outputs[expected & clear]
    np.testing.assert_allclose(tips, forward(motors[expected & clear]), atol=1e-8)


def test_plot_command_writes_pngs(tmp_path, capsys):
    code = cli.main(
        [
            "plot",
            str(MECHANISMS / "five_bar.toml"),
            "--out",
            str(tmp_path),
            "--resolution",
            "16",
        ]
    )
    assert code == 0
    spaces = mpimg.imread(tmp_path / "five_bar_initial.png")
    drawing = mpimg.imread(tmp_path / "five_bar_initial_mechanism.png")
    assert spaces.shape[:2] == (520, 1200)
    assert drawing.shape[:2] == (650, 650)
    assert spaces[..., :3].std() > 0.1  # not a blank canvas


def test_evaluate_command_json(capsys):
    assert cli.main(["evaluate", str(MECHANISMS / "five_bar.toml"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert len(result["samples"]) == 9
    assert result["reach"] > 0 and result["singularity"] > 0
    assert abs(result["f_design"] - result["reach"] - result["singularity"]) < 1e-12
    sample = result["samples"][4]
    assert sample["target"] == {"x": 0.0, "y": 47.5}
    assert abs(sample["ik"]["reached"]["y"] - 47.5) < 1e-8


def test_bad_design_argument(capsys):
    assert (
        cli.main(
            ["evaluate", str(MECHANISMS / "five_bar.toml"), "--design", "100,37,36"]
        )
        == 2
    )
    assert "base_x = 100 is outside its bounds [5, 45]" in capsys.readouterr().err


def test_verify_fails_on_the_initial_five_bar_for_both_reasons(capsys):
    assert (
        cli.main(
            [
                "verify",
                str(MECHANISMS / "five_bar.toml"),
                "--resolution",
                "21",
                "--json",
            ]
        )
        == 1
    )
    result = json.loads(capsys.readouterr().out)
    assert result["coverage"] < 1.0  # the upper corners are out of reach
    assert (
        result["max_f_sing"] > result["threshold_alpha_minus"]
    )  # forward singularity inside
    assert result["min_sigma_fk"] < 0.01


def test_verify_passes_on_a_box_away_from_singularities(tmp_path, capsys):
    text = (MECHANISMS / "five_bar.toml").read_text()
    text = text.replace("min = -40.0\nmax = 40.0", "min = -10.0\nmax = 10.0").replace(
        "min = 15.0\nmax = 80.0", "min = 58.0\nmax = 72.0"
    )
    path = tmp_path / "small.toml"
    path.write_text(text)
    assert cli.main(["verify", str(path), "--resolution", "21", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert (
        result["coverage"] == 1.0
        and result["max_f_sing"] < result["threshold_alpha_minus"]
    )


def test_three_output_sections_match_direct_solves(tmp_path):
    """A 3R arm (3 motors, tip x/y/z): the plot has one row per section, and each
    section's map agrees with a direct backward solve and f_sing at a probed cell."""
    from conftest import ROOT

    from linkopt._design.plots import plot_spaces, section_maps

    arm = linkopt.load(ROOT / "tests/data/arm_3r.toml")
    ev = linkopt.evaluate(arm)
    assert (
        ev.ik_motors.shape == (8, 3) and float(ev.reach) < 1e-12
    )  # the box is in reach
    rows = section_maps(arm, ev, 9)
    assert [round(float(c[3]), 6) for c in rows] == [34.0, 39.0, 44.0]
    for motors, outputs, _, z in rows:
        assert outputs.feasible.mean() > 0.9
        i, j = 4, 4
        b = np.array([outputs.axis0[i], outputs.axis1[j], z])
        solved = linkopt.solve_bk(arm, b)
        assert bool(solved.converged)
        np.testing.assert_allclose(outputs.outputs[i, j], b, atol=1e-9)
        np.testing.assert_allclose(
            outputs.f_sing[i, j], float(linkopt.f_sing(arm, solved.state)), rtol=1e-6
        )
        assert motors.feasible.all()  # an open chain: every motor value assembles
    png = plot_spaces(arm, ev, tmp_path / "arm.png", resolution=9)
    height, width = mpimg.imread(png).shape[:2]
    assert (width, height) == (1200, 1560)  # three rows of sections
