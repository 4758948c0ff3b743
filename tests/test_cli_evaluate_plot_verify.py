"""``linkopt evaluate | plot | verify``: a design's samples and f_design, its maps and
drawing, and the dense check of its target range."""

import json

import matplotlib.image as mpimg
import numpy as np
from conftest import MECHANISMS

import linkopt
from linkopt._cli.evaluation import evaluation_payload
from linkopt._cli.main import main
from linkopt._engine.readout import output_values


def test_plot_command_writes_pngs(tmp_path, capsys):
    code = main(
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
    assert main(["evaluate", str(MECHANISMS / "five_bar.toml"), "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert len(result["samples"]) == 9
    assert result["reach"] > 0 and result["singularity"] > 0
    assert abs(result["f_design"] - result["reach"] - result["singularity"]) < 1e-12
    sample = result["samples"][4]
    assert sample["target"] == {"x": 0.0, "y": 47.5}
    assert abs(sample["ik"]["reached"]["y"] - 47.5) < 1e-8
    # the initial five-bar has unreachable corners: their IK samples run to the cap
    caps = result["capped_samples"]
    assert 1 <= caps["ik"] <= 9 and 0 <= caps["adversarial"] <= 9


def test_bad_design_argument(capsys):
    assert (
        main(["evaluate", str(MECHANISMS / "five_bar.toml"), "--design", "100,37,36"])
        == 2
    )
    assert "base_x = 100 is outside its bounds [5, 45]" in capsys.readouterr().err


def test_verify_fails_on_the_initial_five_bar_for_both_reasons(capsys):
    assert (
        main(
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
    assert main(["verify", str(path), "--resolution", "21", "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert (
        result["coverage"] == 1.0
        and result["max_f_sing"] < result["threshold_alpha_minus"]
    )


def test_evaluate_reports_outputs_of_the_design_it_evaluated(five_bar_evaluation):
    """Regression: ``evaluate --design`` read the samples' outputs off their states
    with the file's design; where the design moves the output point (here the tip
    joint, which the point ``ee`` sits on) they came out where the file's point
    would be."""
    extra = '[[parameters]]\nname = "tip_y"\njoint = "tip"\ncoordinate = "y"\n'
    text = (
        (MECHANISMS / "five_bar.toml").read_text() + extra + "min = 60.0\nmax = 80.0\n"
    )
    mech = linkopt.loads(text)
    design = np.append(mech.design.p0[:3], 75.0)
    payload = evaluation_payload(mech, five_bar_evaluation, design)
    states = five_bar_evaluation.ik_states
    moved = np.asarray(output_values(mech, states, design=design))
    still = np.asarray(output_values(mech, states))
    assert np.abs(moved - still).max() > 1.0  # the design moves the point
    reported = [list(s["ik"]["reached"].values()) for s in payload["samples"]]
    np.testing.assert_allclose(reported, moved, rtol=0, atol=1e-9)
