"""Synthesis targets (issue 41): the ``[synthesis]`` table and target CSVs, and every
bad input refused with one line naming the file and the field, before any work."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

import linkopt
from linkopt import MechanismFileError
from linkopt.synthesis import load_targets

ROOT = Path(__file__).resolve().parents[1]
MECHANISMS = ROOT / "mechanisms"
FOUR_BAR = (MECHANISMS / "four_bar.toml").read_text()
PATH = """
[synthesis]
kind = "path"
name = "coupler_point"
tolerance = 0.5
"""
GOOD = "[[37.607, 53.431], [16.6, 47.166], [6.452, 34.349], [11.438, 29.001]]"


def _file(tmp_path: Path, text: str, base: str = FOUR_BAR, name="m.toml") -> Path:
    path = tmp_path / name
    path.write_text(base + text)
    return path


def _targets(tmp_path: Path, text: str, base: str = FOUR_BAR, csv=None):
    return load_targets(linkopt.load(_file(tmp_path, text, base)), csv)


def _refused(tmp_path, text, where, words, base=FOUR_BAR, csv=None):
    with pytest.raises(MechanismFileError) as caught:
        _targets(tmp_path, text, base, csv)
    message = str(caught.value)
    assert "\n" not in message
    assert where in message, message
    assert re.search(words, message), message
    return message


def test_the_shipped_path_file_reads_its_six_points_closed():
    mech = linkopt.load(MECHANISMS / "four_bar_path.toml")
    targets = load_targets(mech)
    assert (targets.kind, targets.name, targets.closed) == (
        "path",
        "coupler_point",
        True,
    )
    assert targets.values.shape == (6, 3) and targets.motors is None
    np.testing.assert_array_equal(targets.values[:, 2], 0.0)
    assert targets.tolerance == 0.5


def test_a_csv_replaces_the_table_rows_and_keeps_its_kind_and_tolerance():
    mech = linkopt.load(MECHANISMS / "four_bar_path.toml")
    targets = load_targets(mech, MECHANISMS / "four_bar_path.csv")
    assert targets.values.shape == (20, 3) and targets.closed
    np.testing.assert_allclose(targets.values[0], [37.607, 53.431, 0.0])


def test_file_points_are_read_relative_to_the_mechanism_file(tmp_path):
    (tmp_path / "curve.csv").write_text("x,y,crank\n37.6,53.4,0\n16.6,47.2,1.0\n")
    targets = _targets(tmp_path, PATH + 'file = "curve.csv"\n')
    np.testing.assert_allclose(targets.values[:, :2], [[37.6, 53.4], [16.6, 47.2]])
    np.testing.assert_allclose(targets.motors, [[0.0], [1.0]])


def test_function_pairs_give_the_motor_timing(tmp_path):
    text = """
[synthesis]
kind = "function"
name = "rocker"
tolerance = 0.01
points = [[0.0, 0.0], [1.0, 0.2], [2.0, 0.4]]
"""
    targets = _targets(tmp_path, text)
    np.testing.assert_allclose(targets.values, [0.0, 0.2, 0.4])
    np.testing.assert_allclose(targets.motors, [[0.0], [1.0], [2.0]])


@pytest.mark.parametrize(
    ("text", "where", "words"),
    [
        ("points = [[1.0, 2.0]]\n", "[synthesis].points", "at least 2 points, got 1"),
        (
            "closed = true\npoints = [[1.0, 2.0], [3.0, 4.0]]\n",
            "[synthesis].points",
            "closed path target needs at least 3 points",
        ),
        ("points = [[1.0, nan], [3.0, 4.0]]\n", "[synthesis].points[0]", "finite"),
        (
            "points = [[1.0, 2.0], [3.0, 4.0], [1.0, 2.0]]\n",
            "[synthesis].points[2]",
            "duplicates point 0",
        ),
        (
            f"closed = true\npoints = {GOOD[:-1]}, [37.607, 53.431]]\n",
            "[synthesis].points[4]",
            "repeats its first",
        ),
        (
            "points = [[37.6, 53.4], [5000.0, 0.0]]\n",
            "[synthesis].points[1]",
            "beyond any reach of the design bounds",
        ),
        (
            f"points = {GOOD}\nmotors = [[0.0], [1.0]]\n",
            "[synthesis].points",
            "4 targets but 2 rows of motor timing",
        ),
        (f"points = {GOOD}\nfile = 'x.csv'\n", "[synthesis].points", "either"),
    ],
)
def test_bad_rows_are_refused_naming_the_field(tmp_path, text, where, words):
    _refused(tmp_path, PATH + text, where, words)


def test_an_unknown_point_is_refused_with_the_known_names(tmp_path):
    text = PATH.replace("coupler_point", "tip") + f"points = {GOOD}\n"
    _refused(tmp_path, text, "[synthesis].name", "coupler_point")


def test_an_unknown_kind_is_refused(tmp_path):
    text = PATH.replace('"path"', '"shape"') + f"points = {GOOD}\n"
    _refused(tmp_path, text, "[synthesis].kind", "path")


def test_a_point_on_the_ground_is_refused(tmp_path):
    base = FOUR_BAR + '\n[[points]]\nname = "pivot"\nbody = "ground"\n'
    base += "position = [0.0, 0.0, 0.0]\n"
    text = PATH.replace("coupler_point", "pivot") + f"points = {GOOD}\n"
    _refused(tmp_path, text, "[synthesis].name", "ground body", base=base)


def _limited(low: float, high: float) -> str:
    return FOUR_BAR.replace(
        'name = "crank"\njoint = "A"',
        f'name = "crank"\njoint = "A"\nmin = {low}\nmax = {high}',
    )


def test_a_closed_curve_needs_a_full_turn_crank(tmp_path):
    text = PATH + f"closed = true\npoints = {GOOD}\n"
    _refused(tmp_path, text, "[synthesis].closed", "allow 2 rad", base=_limited(-1, 1))


def test_a_closed_curve_needs_a_rotary_motor(tmp_path):
    base = (MECHANISMS / "slider_crank_linear.toml").read_text()
    text = PATH.replace("coupler_point", "crank_pin")
    text += "closed = true\npoints = [[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0]]\n"
    _refused(tmp_path, text, "[synthesis].closed", "rotary motor", base=base)


def test_timing_outside_the_motor_range_is_refused(tmp_path):
    text = PATH + f"points = {GOOD}\nmotors = [[0.0], [0.5], [0.9], [1.5]]\n"
    _refused(tmp_path, text, "[synthesis].points[3]", "outside", base=_limited(-1, 1))


def test_a_function_target_on_a_two_motor_file_is_refused(tmp_path):
    base = (MECHANISMS / "five_bar.toml").read_text()
    name = linkopt.load(MECHANISMS / "five_bar.toml").output_names[0]
    text = f"""
[synthesis]
kind = "function"
name = "{name}"
tolerance = 0.01
points = [[0.0, 0.0], [0.1, 0.1]]
"""
    _refused(tmp_path, text, "[synthesis].kind", "one-motor mechanism", base=base)


@pytest.mark.parametrize(
    ("csv", "where", "words"),
    [
        ("x,y,w\n1,2,3\n3,4,5\n", "column 'w'", "unknown column"),
        ("x\n1\n3\n", "column 'y'", "missing"),
        ("x,y\n1,2\n3,oops\n", "line 3", "expected numbers"),
        ("", "header", "empty file"),
    ],
)
def test_a_bad_csv_is_refused_naming_the_file_and_column(tmp_path, csv, where, words):
    (tmp_path / "t.csv").write_text(csv)
    message = _refused(
        tmp_path, PATH + f"points = {GOOD}\n", where, words, csv=tmp_path / "t.csv"
    )
    assert "t.csv" in message


def test_the_reach_bound_holds_the_file_design_curve():
    """Every point of the file design's own coupler curve is within the bound."""
    from linkopt._synth.targets import reach_bound

    mech = linkopt.load(MECHANISMS / "four_bar.toml")
    turn = np.linspace(0.0, 2 * np.pi, 24, endpoint=False)[:, None]
    states = linkopt.solve_fk_path(mech, turn).state
    curve = np.asarray(linkopt.point_positions(mech, states))[:, 0]
    far, reach = reach_bound(mech, curve)
    assert np.all(far <= reach)
    # and a point twice the reach away is out of it
    far, reach = reach_bound(mech, np.array([[2.5 * reach, 0.0, 0.0]]))
    assert far[0] > reach


def test_the_least_transmission_angle_defaults_to_30_and_is_read(tmp_path):
    assert _targets(tmp_path, PATH + f"points = {GOOD}\n").min_transmission_deg == 30
    text = PATH + f"points = {GOOD}\nmin_transmission_deg = 42.5\n"
    assert _targets(tmp_path, text).min_transmission_deg == 42.5
    text = PATH + f"points = {GOOD}\nmin_transmission_deg = 0\n"
    assert _targets(tmp_path, text).min_transmission_deg == 0.0


@pytest.mark.parametrize("value", ["90", "-1", "'wide'", "nan"])
def test_a_least_transmission_angle_outside_0_90_is_refused(tmp_path, value):
    text = PATH + f"points = {GOOD}\nmin_transmission_deg = {value}\n"
    _refused(tmp_path, text, "[synthesis].min_transmission_deg", r"\[0, 90\)")
