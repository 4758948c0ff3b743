"""Space maps show link clearance (issue 30): with ``[collision]`` enabled every map
cell holds the least clearance between the checked links in its solved state, the
clearance of the link segments between the joints that a brute-force search finds;
a design built in layers has no cell closer than the clearance; the space plot draws
the clearance maps below the ``f_sing`` maps, and leaves them out on request or
without ``[collision]``."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import linkopt
from linkopt._design.maps import finish_map, grid_axes, motor_map, solve_grid
from linkopt._draw.space_plots import plot_spaces
from linkopt._engine.geometry import rest_state
from linkopt._engine.readout import joint_positions

ROOT = Path(__file__).resolve().parents[1]
FIVE_BAR = ROOT / "mechanisms" / "five_bar.toml"
#: Links 16 mm thick (radius 8), clearance 4 mm: in one plane, the five-bar's links
#: come closer than that in parts of its motor space (a crank and the other distal
#: link, about 10 mm apart where the continuation stops).
RADIUS = 8.0
COLLISION = f"\n[collision]\nthickness = {2 * RADIUS}\nclearance = 4.0\n"
#: Layers at least 20 mm apart for every checked pair (pairs that share no joint):
#: the 20 mm (two radii and the clearance) a clear pair needs.
LAYERS = {"crank_left": -40.0, "crank_right": 40.0, "distal_left": -20.0}
LAYERS["distal_right"] = 20.0
LOW, HIGH = np.array([-1.6, -1.6]), np.array([1.6, 1.6])


def _five_bar(layers: bool = False, collision: bool = True):
    text = FIVE_BAR.read_text()
    for name, layer in LAYERS.items() if layers else ():
        body = f'name = "{name}"\n'
        text = text.replace(body, f"{body}layer = {layer}\n", 1)
    return linkopt.loads(text + (COLLISION if collision else ""), "five_bar_c.toml")


def _segment_distance(p1, q1, p2, q2, count: int = 801) -> float:
    """Least distance between two segments by brute force over ``count`` points of
    each."""
    t = np.linspace(0.0, 1.0, count)[:, None]
    a, b = p1 + t * (q1 - p1), p2 + t * (q2 - p2)
    return float(np.min(np.linalg.norm(a[:, None] - b[None], axis=-1)))


def _brute_clearance(mech, joints: np.ndarray) -> float:
    """Least clearance between the bodies that share no joint, each the capsule
    (radius ``RADIUS``) of the segment between its two joints (the ground's: its two
    base joints), from the joints' positions."""
    ends = [
        [k for k, pair in enumerate(mech.joint_bodies) if b in pair]
        for b in range(mech.num_bodies)
    ]
    least = np.inf
    for a, b in itertools.combinations(range(mech.num_bodies), 2):
        if set(ends[a]) & set(ends[b]):
            continue
        gap = _segment_distance(*joints[ends[a]], *joints[ends[b]]) - 2 * RADIUS
        least = min(least, gap)
    return least


def test_map_cells_hold_the_clearance_of_their_states():
    mech = _five_bar()
    axes = grid_axes(LOW, HIGH, 9)
    states, feasible = solve_grid(mech, "fk", axes, np.zeros(2), rest_state(mech), None)
    grid = finish_map(mech, axes, states, feasible, None)
    assert feasible.sum() > 20 and np.all(np.isnan(grid.clearance[~feasible]))
    expected = linkopt.clearance(mech, states[feasible]).minimum
    np.testing.assert_allclose(grid.clearance[feasible], expected, rtol=1e-12)
    joints = np.asarray(joint_positions(mech, states[feasible]))
    brute = [_brute_clearance(mech, j) for j in joints]
    np.testing.assert_allclose(grid.clearance[feasible], brute, atol=0.05)
    # all in one plane, the links come within the clearance somewhere on the map
    assert np.nanmin(grid.clearance) < mech.collision.clearance


def test_a_layered_design_has_no_cell_below_the_clearance():
    mech = _five_bar(layers=True)
    grid = motor_map(
        mech, LOW, HIGH, 9, start_state=rest_state(mech), start_motors=np.zeros(2)
    )
    assert grid.feasible.sum() > 20
    assert np.nanmin(grid.clearance) >= mech.collision.clearance
    plain = _five_bar(collision=False)
    rest = rest_state(plain)
    grid = motor_map(plain, LOW, HIGH, 5, start_state=rest, start_motors=np.zeros(2))
    assert grid.clearance is None


def _rest_evaluation(mech) -> linkopt.Evaluation:
    """An evaluation whose one IK and adversarial sample are the rest pose: what the
    plot draws, without the cost of evaluating."""
    rest = np.asarray(rest_state(mech))[None]
    zero, motors = np.zeros(()), np.zeros((1, mech.num_motors))
    return linkopt.Evaluation(
        *(zero,) * 4, motors, rest, np.zeros(1), np.ones(1), motors, rest,
        np.ones(1), np.zeros(1), np.zeros(1, int), np.zeros(1, int),
    )  # fmt: skip


@pytest.mark.parametrize(
    "collision, clearance, rows", [(True, True, 2), (True, False, 1), (False, True, 1)]
)
def test_the_plot_draws_clearance_maps_below_the_f_sing_maps(
    collision, clearance, rows, tmp_path
):
    mech = _five_bar(collision=collision)
    path = plot_spaces(
        mech,
        _rest_evaluation(mech),
        tmp_path / "spaces.png",
        resolution=8,
        clearance=clearance,
    )
    width, height = Image.open(path).size
    assert (width, height) == (1200, 520 * rows)


def test_the_drawing_of_a_collision_file_adds_a_side_view(tmp_path):
    """A planar mechanism with ``[collision]`` is drawn in its plane and from the side,
    where a lift out of the plane shows; one without it in its plane only."""
    from linkopt._draw.plots import plot_mechanism

    lifted = linkopt.load(ROOT / "mechanisms" / "four_bar_collision.toml")
    designs = {"initial": None, "lifted": np.array([-5.0])}
    path = plot_mechanism(lifted, tmp_path / "lifted.png", designs=designs)
    assert Image.open(path).size == (750, 900)  # the side view below the top view
    plain = linkopt.load(ROOT / "mechanisms" / "four_bar.toml")
    path = plot_mechanism(plain, tmp_path / "plain.png")
    assert Image.open(path).size == (650, 650)
