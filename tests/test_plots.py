"""Continuation maps against the five-bar closed form, and the space plots of three
outputs (the plot/evaluate/verify commands: test_cli_evaluate_plot_verify.py)."""

import matplotlib.image as mpimg
import numpy as np
from five_bar_closed_form import L2, elbows, forward
from scipy import ndimage

import linkopt
from linkopt._design import maps
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


def test_a_map_reads_its_feasible_cells_only(five_bar, monkeypatch):
    """finish_map reads f_sing and the motor and output values of the feasible cells
    (equal to reading every state one batch), NaN elsewhere, whatever an infeasible
    cell holds; with no feasible cell it reads nothing."""
    rng = np.random.default_rng(0)
    rest = np.asarray(linkopt.rest_state(five_bar))
    motors = rng.uniform(-0.2, 0.2, (12, 2))
    states = np.asarray(linkopt.solve_fk(five_bar, motors, start=rest).state)
    states = states.reshape(3, 4, -1).copy()
    feasible = rng.random((3, 4)) < 0.6
    states[~feasible] = np.nan  # what a failed cell holds must not matter
    axes = [np.arange(3.0), np.arange(4.0)]
    grid = maps.finish_map(five_bar, axes, states, feasible, None)
    ok = states[feasible]
    np.testing.assert_array_equal(grid.f_sing[feasible], linkopt.f_sing(five_bar, ok))
    np.testing.assert_allclose(grid.motors[feasible], motors.reshape(3, 4, 2)[feasible])
    np.testing.assert_array_equal(
        grid.outputs[feasible], linkopt.output_values(five_bar, ok)
    )
    assert np.isnan(grid.f_sing[~feasible]).all()
    assert np.isnan(grid.outputs[~feasible]).all()

    def unread(*_, **__):
        raise AssertionError("read with no feasible cell")

    monkeypatch.setattr(maps, "f_sing", unread)
    monkeypatch.setattr(maps, "output_values", unread)
    none = maps.finish_map(five_bar, axes, states, np.zeros((3, 4), bool), None)
    assert np.isnan(none.f_sing).all() and np.isnan(none.outputs).all()


def test_three_output_sections_match_direct_solves(tmp_path):
    """A 3R arm (3 motors, tip x/y/z): the plot has one row per section, and each
    section's map agrees with a direct backward solve and f_sing at a probed cell."""
    from conftest import ROOT

    from linkopt._draw.plot_maps import section_maps
    from linkopt._draw.space_plots import plot_spaces

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
        # every motor section cuts the target range's image, so its outline is drawn
        # (sections at the IK samples' extreme third motor values only touched it)
        inside = (motors.outputs >= arm.output_min) & (motors.outputs <= arm.output_max)
        assert np.all(inside, axis=-1).sum() >= 2
    png = plot_spaces(arm, ev, tmp_path / "arm.png", resolution=9)
    height, width = mpimg.imread(png).shape[:2]
    assert (width, height) == (1200, 1560)  # three rows of sections


def test_maps_read_reported_outputs_over_their_cells(five_bar, tmp_path):
    """A reported output that is the tip's x again: the map's reported values are its
    outputs' x on every reached cell and NaN elsewhere, and the space plot draws it."""
    from conftest import MECHANISMS

    from linkopt._design.evaluation import evaluate
    from linkopt._draw.space_plots import plot_spaces

    text = (MECHANISMS / "five_bar.toml").read_text()
    extra = (
        '[[outputs]]\nname = "tip_x"\npoint = "ee"\ncoordinate = "x"\nreported = true\n'
    )
    mech = linkopt.loads(
        text.replace("# Mirror symmetry", extra + "\n# Mirror symmetry")
    )
    assert list(mech.reported_table.names) == ["tip_x"]
    grid = motor_map(
        mech,
        [-1.5, -1.5],
        [1.5, 1.5],
        9,
        start_state=linkopt.rest_state(mech),
        start_motors=[0.0, 0.0],
    )
    assert grid.reported.shape == (9, 9, 1)
    assert grid.feasible.any() and (~grid.feasible).any()
    np.testing.assert_allclose(
        grid.reported[grid.feasible, 0], grid.outputs[grid.feasible, 0], atol=1e-9
    )
    assert np.isnan(grid.reported[~grid.feasible]).all()
    plain = motor_map(
        five_bar,
        [-1.5, -1.5],
        [1.5, 1.5],
        9,
        start_state=linkopt.rest_state(five_bar),
        start_motors=[0.0, 0.0],
    )
    assert plain.reported is None  # no reported output: no read-out
    out = plot_spaces(mech, evaluate(mech), tmp_path / "spaces.png", resolution=9)
    assert mpimg.imread(out).shape[2] in (3, 4)


def test_plotting_leaves_the_users_backend_and_pyplot_alone(tmp_path):
    """linkopt draws on figures of its own (no matplotlib.use, no pyplot): a user's
    backend stays as chosen and pyplot holds no figure of linkopt's afterwards."""
    import subprocess
    import sys

    code = (
        "import matplotlib\n"
        "matplotlib.use('svg')\n"
        "import matplotlib.pyplot as plt\n"
        "import linkopt._draw.plots as plots, linkopt._draw.animation\n"
        "import linkopt._draw.arms.trace, linkopt._draw.arms.codesign\n"
        "import linkopt._draw.arms.dh\n"
        "keys = ('best_total', 'best_f_design', 'reach', 'singularity', "
        "'regularizer')\n"
        "history = [{'iteration': k, **{key: 1.0 / (k + 1) for key in keys}} "
        "for k in range(3)]\n"
        f"plots.plot_convergence(history, {str(tmp_path / 'c.png')!r})\n"
        "assert matplotlib.get_backend() == 'svg', matplotlib.get_backend()\n"
        "assert plt.get_fignums() == [], plt.get_fignums()\n"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=300
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert (tmp_path / "c.png").stat().st_size > 0
