"""The final outputs (issue 20, parts 6 and 7): 2-D sections solved in their planes
agree with the fine 3-D continuation they replace, the maps report progress, the
drawing of a spatial mechanism has three views, and the history's ``best_total`` is
the running best, across a resume."""

import dataclasses
import json

import matplotlib.image as mpimg
import numpy as np
import pytest
from conftest import ROOT

import linkopt
from linkopt._design import maps
from linkopt._design.checkpoint import decode, encode
from linkopt._design.optimizer import OptimizerSettings, reopen, score, start
from linkopt._draw.plots import plot_mechanism

ARM = ROOT / "tests/data/arm_3r.toml"
#: An output window reaching past the arm's reach (60 mm from the shoulder), so that
#: the sections have unreached cells; the box is the arm file's target box.
LOW, HIGH = np.array([20.0, -10.0, 30.0]), np.array([70.0, 10.0, 60.0])
CUTS = [34.0, 39.0, 44.0]


@pytest.fixture(scope="module")
def arm():
    return linkopt.load(ARM)


def test_sections_agree_with_the_fine_3d_grid(arm):
    rest = linkopt.rest_state(arm)
    start_b = np.asarray(linkopt.output_values(arm, rest))
    records = []
    new = maps.sections(
        arm,
        "bk",
        LOW,
        HIGH,
        9,
        CUTS,
        start_state=rest,
        start_values=start_b,
        depth=5,
        progress=records.append,
    )
    # the replaced method: one fine 3-D continuation through every cut
    third = maps.merged_values(LOW[2], HIGH[2], 5, [*CUTS, start_b[2]])
    axes = maps.grid_axes(LOW[:2], HIGH[:2], 9) + [third]
    states, feasible = maps.solve_grid(arm, "bk", axes, start_b, rest, None)
    for section, cut in zip(new, CUTS):
        k = int(np.argmin(np.abs(third - cut)))
        old = maps.finish_map(arm, axes, states[:, :, k], feasible[:, :, k], None)
        assert 0.2 < section.feasible.mean() < 0.95  # a reach boundary is crossed
        assert (section.feasible == old.feasible).mean() >= 0.95
        both = section.feasible & old.feasible
        np.testing.assert_allclose(section.f_sing[both], old.f_sing[both], rtol=1e-6)
        np.testing.assert_allclose(section.outputs[..., 2][both], cut, atol=1e-9)
    stages = list(dict.fromkeys(r["stage"] for r in records))
    assert stages == ["BK sections: coarse 3-D grid"] + [
        f"BK section {k} of 3" for k in (1, 2, 3)
    ]
    for stage in stages:
        counts = [r["cells"] for r in records if r["stage"] == stage]
        assert counts == sorted(counts) and counts[-1] <= records[-1]["of"] * 13


def test_plot_cost_of_three_outputs_is_a_fraction_of_the_3d_grid(arm):
    """The default three-output figure solves under a seventh of the cells of the
    fine 3-D grids (60² x 13 per space) it replaces: 6 x 40² + 2 x 10² x 13 cells
    against 2 x 60² x 13."""
    resolution = maps.plot_resolution(arm)
    assert resolution == maps.PLOT_RESOLUTION[3]
    new = maps.plot_cost(arm, resolution).seconds
    old = maps.grid_cost(arm, (60, 60, maps.SECTION_CELLS), 3600, grids=2).seconds
    assert new < old / 7


def test_spatial_mechanism_is_drawn_in_three_views(arm, tmp_path):
    # the arm turns about z at its base: spatial, though its anchors lie in y = 0
    assert mpimg.imread(plot_mechanism(arm, tmp_path / "arm.png")).shape[1] == 3 * 650
    five_bar = linkopt.load(ROOT / "mechanisms" / "five_bar.toml")  # planar
    planar = plot_mechanism(five_bar, tmp_path / "planar.png")
    assert mpimg.imread(planar).shape[1] == 650
    text = ARM.read_text()  # the elbow moved along its axis (y): out of that plane
    assert text.count("anchor = [0.0, 0.0, 40.0]") == 1
    text = text.replace("anchor = [0.0, 0.0, 40.0]", "anchor = [0.0, 5.0, 40.0]")
    path = tmp_path / "spatial.toml"
    path.write_text(text)
    spatial = plot_mechanism(linkopt.load(path), tmp_path / "spatial.png")
    assert mpimg.imread(spatial).shape[1] == 3 * 650


class _Ev:
    """The four per-particle arrays :func:`score` reads, with
    ``f_design`` = 0.9 of the total and the regulariser the rest."""

    def __init__(self, totals):
        totals = np.asarray(totals, float)
        self.f_design = 0.9 * totals
        self.regularizer = 0.1 * totals
        self.reach = 0.5 * self.f_design
        self.singularity = 0.5 * self.f_design


SETTINGS = OptimizerSettings(particles=2, iterations=10, seed=0)
ITERATIONS = [[3.0, 4.0], [5.0, 1.0], [2.0, 6.0], [0.5, 9.0], [np.nan, 7.0]]


def _advance(run, totals, settings=SETTINGS):
    run, _ = score(FIVE_BAR, run, _Ev(totals), settings)
    *done, last = run.history
    return dataclasses.replace(
        run,
        iteration=run.iteration + 1,
        history=(*done, {**last, "wall_time": float(run.iteration)}),
    )


FIVE_BAR = linkopt.load(ROOT / "mechanisms/five_bar.toml")


def test_best_total_is_the_returned_designs_and_survives_a_resume(tmp_path):
    """Nothing feasible (``f_design`` far above the tolerance): the returned design
    is the lowest total seen."""
    five_bar = FIVE_BAR
    run = start(five_bar, SETTINGS)
    for totals in ITERATIONS[:2]:
        run = _advance(run, totals)
    data = json.loads(json.dumps(encode(run, five_bar, SETTINGS), allow_nan=True))
    resumed = decode(tmp_path / "checkpoint.json", data, five_bar, SETTINGS)
    for totals in ITERATIONS[2:]:
        run, resumed = _advance(run, totals), _advance(resumed, totals)
    best = [h["best_total"] for h in run.history]
    assert best == [h["best_total"] for h in resumed.history] == [3, 1, 1, 0.5, 0.5]
    assert [h["iteration_total"] for h in run.history] == [3, 1, 2, 0.5, 7]
    for h in run.history:  # the parts are the returned design's
        assert h["best_f_design"] + h["regularizer"] == pytest.approx(h["best_total"])
        assert not h["feasible"]
    # a verification round changes the targets: the numbers start again
    rounds = ({"added_targets": [[0.0, 40.0]]},)
    again = reopen(dataclasses.replace(run, finished=True, rounds=rounds), SETTINGS)
    after = _advance(again, [8.0, 9.0])
    assert after.history[-1]["best_total"] == 8.0 and after.history[-1]["round"] == 1


def test_the_history_follows_the_returned_design_feasible_first():
    """Regression (issues 44, 45): the progress line paired the lowest f_design of any
    iteration with another design's regulariser, and history.csv's running best
    (lowest total) was not the returned design (feasible first). Here particle 1 is
    feasible (f_design ≤ tolerance) from the second iteration, with a higher total than
    particle 0: the record is particle 1's from then on, and the returned design's key
    (infeasible, total) never rises."""
    settings = dataclasses.replace(SETTINGS, tolerance=0.05)
    run = start(FIVE_BAR, settings)
    # (f_design, regulariser) of particles 0 and 1: particle 0 is never feasible
    for pairs in (
        [(3.0, 0.0), (4.0, 0.0)],
        [(0.5, 0.0), (0.01, 1.09)],
        [(0.2, 0.0), (0.02, 1.03)],
        [(0.1, 0.0), (0.03, 1.05)],
        [(0.4, 0.0), (0.04, 0.86)],
    ):
        run = _advance_by(run, pairs, settings)
    history = run.history
    assert [h["feasible"] for h in history] == [False, True, True, True, True]
    assert [h["best_total"] for h in history] == pytest.approx(
        [3.0, 1.1, 1.05, 1.05, 0.9]
    )
    assert [h["best_f_design"] for h in history] == [3.0, 0.01, 0.02, 0.02, 0.04]
    assert [h["regularizer"] for h in history] == [0.0, 1.09, 1.03, 1.03, 0.86]
    assert [h["iteration_total"] for h in history] == [3.0, 0.5, 0.2, 0.1, 0.4]
    np.testing.assert_array_equal(history[-1]["best_design"], run.position[1])
    keys = [(not h["feasible"], h["best_total"]) for h in history]
    assert all(b <= a for a, b in zip(keys, keys[1:]))
    from linkopt._cli.optimize import iteration_line

    line = iteration_line(history[2])
    assert "best f_design 2.0000e-02, regulariser 1.03e+00 (feasible;" in line


def _advance_by(run, pairs, settings):
    """:func:`_advance` with each particle's ``f_design`` and regulariser given."""
    ev = _Ev([0.0] * len(pairs))
    ev.f_design = np.array([p[0] for p in pairs])
    ev.regularizer = np.array([p[1] for p in pairs])
    ev.reach, ev.singularity = ev.f_design, 0.0 * ev.f_design
    run, _ = score(FIVE_BAR, run, ev, settings)
    *done, last = run.history
    last = {**last, "wall_time": float(run.iteration)}
    return dataclasses.replace(run, iteration=run.iteration + 1, history=(*done, last))
