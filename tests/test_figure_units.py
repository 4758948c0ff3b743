"""Figure axes carry the file's units (issue 44): a linear motor's axis is in the
file's length unit, not "(length)"; a revolute motor's and an angle output's in rad."""

from pathlib import Path

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._design.evaluation import Evaluation, targets
from linkopt._draw import figures as _figures
from linkopt._draw import labels
from linkopt._draw.space_plots import plot_spaces
from linkopt._files.fields import parse_toml
from linkopt._files.loader import build

BIGLIDE = Path(__file__).with_name("biglide.toml")


def parsed(text: str) -> linkopt.Mechanism:
    """The mechanism as read from its file, without the load-time checks (labels
    depend on the file's tables only; no program compiles)."""
    return build(parse_toml(text, "<test>"), "<test>", check=False)


def test_labels_follow_each_motor_and_output_kind():
    stewart = parsed((MECHANISMS / "stewart.toml").read_text())
    assert set(labels.motor_labels(stewart)) == {
        f"motor {n} (mm)" for n in stewart.motor_names
    }
    slider = parsed((MECHANISMS / "slider_crank_linear.toml").read_text())
    assert labels.motor_labels(slider) == ["motor slide (mm)"]
    assert labels.output_labels(slider) == ["output crank_angle (rad)"]
    five_bar = parsed((MECHANISMS / "five_bar.toml").read_text())
    assert labels.motor_labels(five_bar) == ["motor left (rad)", "motor right (rad)"]
    assert labels.output_labels(five_bar) == ["output x (mm)", "output y (mm)"]
    unnamed = parsed(BIGLIDE.read_text().replace('units = "mm"\n', ""))
    assert labels.motor_unit(unnamed, 0) == "length units"


def solved_samples(mech: linkopt.Mechanism) -> Evaluation:
    """An evaluation whose IK and adversarial samples are the poses that BK solves at
    the file's targets (scores zero): what the space plot reads from an evaluation,
    without compiling the biglide's whole evaluation, about half of this test's CPU
    cold (the axes' labels do not depend on how the samples were found; the
    five-bar's space plots draw real evaluations)."""
    # warm-started from the rest pose: the maps' solve program (from_rest_bk, the
    # continuation from rest, would be one more to compile)
    solved = linkopt.solve_bk(mech, targets(mech), start=linkopt.rest_state(mech))
    states = np.asarray(solved.state)[np.asarray(solved.converged)]
    assert len(states) >= 2
    motors = np.asarray(linkopt.motor_values(mech, states)) / mech.motor_scale
    f_sing = np.asarray(linkopt.f_sing(mech, states))
    zero, count = np.float64(0.0), np.zeros(len(states), dtype=int)
    return Evaluation(
        f_design=zero, reach=zero, singularity=zero, regularizer=zero,
        ik_motors=motors, ik_states=states, ik_reach=0.0 * f_sing, ik_f_sing=f_sing,
        adv_motors=motors, adv_states=states, adv_f_sing=f_sing,
        adv_culled=0.0 * f_sing, ik_iterations=count, adv_iterations=count,
    )  # fmt: skip


@pytest.mark.slow
def test_a_linear_motors_map_axis_is_in_the_files_unit(tmp_path, monkeypatch):
    """The biglide's two slider motors, on its motor-space map."""
    made = []

    def subplots(*args, **kwargs):
        fig, axes = original(*args, **kwargs)
        made.append(fig)
        return fig, axes

    original = _figures.subplots
    monkeypatch.setattr(_figures, "subplots", subplots)
    mech = linkopt.load(BIGLIDE)
    plot_spaces(mech, solved_samples(mech), tmp_path / "spaces.png", resolution=8)
    (fig,) = made
    motor_axes, output_axes = fig.axes[:2]
    assert motor_axes.get_xlabel() == "motor left (mm)"
    assert motor_axes.get_ylabel() == "motor right (mm)"
    assert output_axes.get_xlabel() == "output x (mm)"


def test_the_mechanism_figures_axes_are_in_the_files_unit(tmp_path, monkeypatch):
    from linkopt._draw.plots import plot_mechanism

    made = []
    original = _figures.subplots

    def subplots(*args, **kwargs):
        fig, axes = original(*args, **kwargs)
        made.append(fig)
        return fig, axes

    monkeypatch.setattr(_figures, "subplots", subplots)
    mech = linkopt.load(MECHANISMS / "slider_crank_linear.toml")
    plot_mechanism(mech, tmp_path / "m.png")
    (fig,) = made
    assert (fig.axes[0].get_xlabel(), fig.axes[0].get_ylabel()) == ("x (mm)", "y (mm)")
