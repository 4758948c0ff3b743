"""``linkopt view`` without a browser (issue 42): the motor grid's reached cells are
assembled configurations at their grid's motor values, the page holds them so that a
point posed as the page poses it is where the engine puts it, the page of every shipped
mechanism stays under 10 MB, a run folder's page holds both designs, and bad input
exits 2 with one line before any solve. The page in a real browser:
``tests/test_view_browser.py``."""

import json
import os
import re
import shutil
from pathlib import Path

import numpy as np
import pytest

import linkopt
from linkopt._cli.main import main
from linkopt._design import view_grid as view_grid_module
from linkopt._design.view_grid import (
    ViewGrid,
    check_view_grid,
    default_resolution,
    largest_resolution,
    motor_window,
    view_grid,
)
from linkopt._draw.view import Shown, view_data, view_html
from linkopt._engine.geometry import rest_state
from linkopt._engine.readout import motor_values, point_positions

ROOT = Path(__file__).resolve().parent.parent
MECHANISMS = sorted((ROOT / "mechanisms").glob("*.toml"))
FIVE_BAR = ROOT / "mechanisms" / "five_bar.toml"


def _run(capsys, *argv):
    code = main([str(a) for a in argv])
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def stewart():
    return linkopt.load(str(ROOT / "mechanisms" / "stewart.toml"))


@pytest.fixture(scope="module")
def five_bar_grid(five_bar):
    return view_grid(five_bar, 9)


def test_reached_cells_are_assemblies_at_their_motor_values(five_bar, five_bar_grid):
    grid = five_bar_grid
    motors = np.stack(np.meshgrid(*grid.axes, indexing="ij"), -1).reshape(-1, 2)
    ok = grid.feasible
    assert 0 < ok.sum() < len(ok)  # the window reaches past the rest branch's edge
    reached = np.asarray(motor_values(five_bar, grid.states[ok]))
    assert np.max(np.abs(reached - motors[ok])) < 1e-8
    assert np.all(np.isnan(grid.states[~ok])) and np.all(np.isnan(grid.f_sing[~ok]))
    assert np.all(grid.f_sing[ok] > 0)
    assert np.allclose(motors[grid.rest_cell], 0.0)
    assert np.allclose(grid.states[grid.rest_cell], rest_state(five_bar), atol=1e-9)


def _turn(q, v):
    """``v`` turned by the unit quaternion ``q`` (wxyz), as the page's script does."""
    w, u = q[0], np.asarray(q[1:])
    t = 2 * np.cross(u, v)
    return v + w * t + np.cross(u, t)


def test_page_data_pose_the_points_where_the_engine_puts_them(five_bar, five_bar_grid):
    data = view_data(five_bar, [Shown("file", None, five_bar_grid)])
    (design,) = data["designs"]
    ok = np.flatnonzero(five_bar_grid.feasible)
    engine = np.asarray(point_positions(five_bar, five_bar_grid.states[ok]))
    for row, k in enumerate(ok):
        state = np.array(design["states"][k]).reshape(-1, 7)
        for p, point in enumerate(design["points"]):
            s = state[point["body"]]
            at = five_bar.length_scale * s[:3] + _turn(s[3:], np.array(point["local"]))
            assert np.linalg.norm(at - engine[row, p]) < 1e-7 * five_bar.length_scale
    failed = np.flatnonzero(~five_bar_grid.feasible)
    assert all(design["states"][k] is None for k in failed)
    assert data["target"] == {"point": "ee", "box": [[-40.0, 40.0], [15.0, 80.0], None]}


def _worst_grid(mech, resolution: int) -> ViewGrid:
    """Every cell reached, each state number nine significant digits long: the
    largest page a grid of this size can make (no solve)."""
    cells = resolution**mech.num_motors
    rng = np.random.default_rng(0)
    rest = np.asarray(rest_state(mech))
    states = rest + 1e-3 * rng.uniform(-1, 1, (cells, rest.size)) + 1e-12
    axes = tuple(
        np.linspace(lo, hi, resolution)
        for lo, hi in zip(*motor_window(mech, resolution))
    )
    clearance = None if mech.collision is None else rng.uniform(0.1, 1, cells)
    return ViewGrid(
        axes, states, np.ones(cells, bool), rng.uniform(1, 50, cells), clearance, 0
    )


@pytest.mark.parametrize("path", MECHANISMS, ids=lambda p: p.stem)
def test_every_shipped_page_is_under_10_mb(path):
    mech = linkopt.load(str(path))
    resolution = default_resolution(mech)
    assert resolution == check_view_grid(mech, None)
    assert resolution >= 3
    page = view_html(mech, [Shown("file", None, _worst_grid(mech, resolution))])
    assert len(page.encode()) < 10e6
    assert "cdn" not in re.sub(r"<script>.*?</script>", "", page, flags=re.S).lower()


def test_a_run_folder_page_holds_both_designs(tmp_path, capsys):
    mech = linkopt.load(str(FIVE_BAR))
    initial = mech.design.p0 + 0.3 * (mech.design.upper - mech.design.p0)
    shutil.copy(FIVE_BAR, tmp_path / "optimized.toml")
    summary = {"initial_design": dict(zip(mech.design.names, initial.tolist()))}
    (tmp_path / "summary.json").write_text(json.dumps(summary))
    code, out, err = _run(capsys, "view", tmp_path, "--resolution", "5")
    assert code == 0, err
    page = (tmp_path / "view.html").read_text()
    data = json.loads(re.search(r"id='linkopt-data'>(.*?)</script>", page).group(1))
    labels = [d["label"] for d in data["designs"]]
    assert labels == ["initial", "optimised"]
    # the initial design's elbow sits where its design puts it (elbow_x, elbow_y)
    ground, crank_right = (data["designs"][0]["bodies"][b] for b in (0, 2))
    elbow = np.array(crank_right["joints"][1]) + mech.body_origins[2]
    assert np.allclose(elbow[:2], initial[1:3], atol=1e-6)
    assert "view.html" in out


def test_too_many_motors_for_the_grid_says_what_it_costs(capsys, tmp_path):
    out = tmp_path / "v.html"
    code, _, err = _run(
        capsys, "view", ROOT / "mechanisms" / "stewart.toml", "--resolution", "10",
        "--out", out,
    )  # fmt: skip
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "10^6 = 1e+06 configurations" in err and "MB" in err
    stewart = linkopt.load(str(ROOT / "mechanisms" / "stewart.toml"))
    assert f"--resolution {largest_resolution(stewart)} or less" in err
    assert largest_resolution(stewart) == 3
    assert not out.exists()


def test_a_mechanism_with_too_many_motors_for_any_grid(capsys, monkeypatch):
    # a page budget of 50 kB: the Stewart platform's 2^6 cells take 90 kB
    monkeypatch.setattr(view_grid_module, "MAX_DATA_BYTES", 50_000)
    code, _, err = _run(capsys, "view", ROOT / "mechanisms" / "stewart.toml")
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "6 motors are too many for a page even at --resolution 2" in err


def test_a_design_file_of_another_mechanism_is_refused(capsys, tmp_path):
    other = tmp_path / "other.toml"
    text = FIVE_BAR.read_text().replace('name = "distal_right"', 'name = "coupler"')
    other.write_text(text.replace('"distal_right"]', '"coupler"]'))
    code, _, err = _run(
        capsys, "view", FIVE_BAR, "--design", other, "--out", tmp_path / "v.html"
    )
    assert code == 2 and len(err.strip().splitlines()) == 1
    assert "same mechanism" in err and "coupler" in err
    delta = ROOT / "mechanisms" / "delta.toml"
    code, _, err = _run(capsys, "view", FIVE_BAR, "--design", delta)
    assert code == 2 and len(err.strip().splitlines()) == 1


def test_out_in_a_missing_folder_is_refused(capsys, tmp_path):
    code, _, err = _run(capsys, "view", FIVE_BAR, "--out", tmp_path / "no" / "v.html")
    assert code == 2 and "does not exist" in err and len(err.strip().splitlines()) == 1
    assert not (tmp_path / "no").exists()


def test_out_in_an_unwritable_folder_is_refused(capsys, tmp_path, monkeypatch):
    # the tests may run as root, whom no permission bit stops: ask as the OS would
    # answer another user
    real = os.access
    folder = tmp_path / "locked"
    folder.mkdir()
    monkeypatch.setattr(
        os, "access", lambda p, mode: False if Path(p) == folder else real(p, mode)
    )
    code, _, err = _run(capsys, "view", FIVE_BAR, "--out", folder / "v.html")
    assert code == 2 and "not writable" in err and len(err.strip().splitlines()) == 1


def test_optimize_writes_the_view_beside_the_figures(tmp_path, monkeypatch, capsys):
    """``linkopt optimize`` (its search and outputs stubbed: a finished run folder)
    writes ``view.html`` with both designs and names it with the figures."""
    import linkopt._design.run as run

    out = tmp_path / "run"
    mech = linkopt.load(str(FIVE_BAR))
    initial = mech.design.p0 + 0.2 * (mech.design.upper - mech.design.p0)

    def outputs(*args, **kwargs):
        out.mkdir(parents=True, exist_ok=True)
        shutil.copy(FIVE_BAR, out / "optimized.toml")
        summary = {"initial_design": dict(zip(mech.design.names, initial.tolist()))}
        (out / "summary.json").write_text(json.dumps(summary))
        return {
            **dict.fromkeys(("iterations", "f_design", "regularizer"), 0),
            **{"verified": True, "initial_verified": True, "at_bounds": {}},
            **{"verification_rounds": [], "design": {}},
            "capped_samples": {"ik": 0, "adversarial": 0},
            "optimized_file": str(out / "optimized.toml"),
        }

    monkeypatch.setattr(run, "optimize", lambda *args, **kwargs: None)
    monkeypatch.setattr(run, "write_outputs", outputs)
    monkeypatch.setattr(view_grid_module, "MAX_DEFAULT_CELLS", 50)  # 5² per design
    assert main(["optimize", str(FIVE_BAR), "--out", str(out)]) == 0
    err = capsys.readouterr().err
    figures = next(x for x in err.splitlines() if x.startswith("figures:"))
    assert str(out / "view.html") in figures
    page = (out / "view.html").read_text()
    data = json.loads(re.search(r"id='linkopt-data'>(.*?)</script>", page).group(1))
    assert [d["label"] for d in data["designs"]] == ["initial", "optimised"]
    assert [len(a) for a in data["designs"][0]["axes"]] == [5, 5]


@pytest.mark.parametrize("resolution", [3, 5, 11, 43])
def test_a_coarse_grid_takes_small_steps(resolution, stewart, five_bar):
    """Without motor limits a grid's steps are at most 0.25 rad and 0.05 reference
    lengths (the Stewart platform's three cells per leg reached 1 of 729 cells with
    steps of 0.25 reference lengths), and the window is the full span when the grid
    is fine enough; rest is a cell of an odd grid."""
    for mech, span in ((stewart, 0.25 * stewart.length_scale), (five_bar, np.pi / 3)):
        low, high = motor_window(mech, resolution)
        step = (high - low) / (resolution - 1)
        limit = np.where(mech.motor_linear, 0.05 * mech.length_scale, 0.25)
        assert np.all(step <= limit * (1 + 1e-12))
        assert np.allclose(high, np.minimum(span, 0.5 * (resolution - 1) * limit))
        assert np.allclose(low, -high)


def test_a_synthesis_files_page_holds_its_targets_and_traced_curve():
    """A file with a ``[synthesis]`` path: each design's curve is the cycle the engine
    traces (the named point's FK at the swept motor values, to 1e-9 of the reference
    length) and the targets are the file's, in order; a file without one has none."""
    from linkopt._synth.cycle import sweep_cycle
    from linkopt._synth.targets import load_targets

    mech = linkopt.load(ROOT / "mechanisms" / "four_bar_path.toml")
    design = mech.design.p0
    shown = [Shown("file's design", None, view_grid(mech, 5, None))]
    (data,) = view_data(mech, shown)["designs"]
    curve = data["curve"]
    targets = load_targets(mech)
    assert curve["kind"] == "path" and curve["name"] == targets.name
    np.testing.assert_allclose(curve["targets"], targets.values[:, :3], atol=1e-8)
    report = sweep_cycle(mech, design, targets)
    assert len(curve["traced"]) == len(report.motors)
    steps = np.flatnonzero(report.solved)[:: max(1, report.solved.size // 12)]
    solved = linkopt.solve_fk(mech, report.motors[steps])
    assert np.all(np.asarray(solved.converged))
    k = mech.point_names.index(targets.name)
    fk = np.asarray(linkopt.point_positions(mech, solved.state))[:, k]
    traced = np.array([curve["traced"][s] for s in steps], dtype=float)
    assert np.abs(traced - fk).max() <= 1e-9 * mech.length_scale + 1e-8
    five = linkopt.load(FIVE_BAR)
    (plain,) = view_data(five, [Shown("x", None, view_grid(five, 3, None))])["designs"]
    assert plain["curve"] is None
