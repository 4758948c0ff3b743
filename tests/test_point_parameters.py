"""Design parameters that place a named point on its body (``kind = "point"``): the
parameter is the point's rest coordinate, the rest of the point still follows its
body's anchors, the path objective's partial gradient with respect to it matches
finite differences, a written design reads back as the same design, bound edits keep
the compiled programs, the closed-form starts place the point, and malformed ones
name their field."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import linkopt
from linkopt._engine.geometry import geometry
from linkopt._engine.lifting import padded
from linkopt._engine.point_moves import box_designs, point_moves
from linkopt._engine.structure import structure
from linkopt._errors import MechanismFileError
from linkopt._files.synthesis import build
from linkopt._files.writer import design_definition, dumps
from linkopt._synth import objective, starts

ROOT = Path(__file__).resolve().parents[1]
FILE = ROOT / "mechanisms" / "four_bar_path.toml"
TEXT = FILE.read_text()
STEPS = 72
#: The coupler point's x and y, free on the coupler around its file place (35, 55).
POINT_PARAMETERS = """
[[parameters]]
name = "tip_x"
kind = "point"
point = "coupler_point"
coordinate = "x"
min = 20.0
max = 50.0

[[parameters]]
name = "tip_y"
kind = "point"
point = "coupler_point"
coordinate = "y"
min = 40.0
max = 70.0
"""


def with_parameters(extra: str = POINT_PARAMETERS, text: str = TEXT) -> str:
    return text.replace("[synthesis]", extra + "\n[synthesis]")


@pytest.fixture(scope="module")
def mech():
    return linkopt.loads(with_parameters(), str(FILE))


def rest_point(mech, design) -> np.ndarray:
    return np.asarray(geometry(mech, design).points)[0] * mech.length_scale


def test_the_parameter_is_the_point_coordinate_and_the_pins_still_move(mech):
    assert mech.design.names[-2:] == ("tip_x", "tip_y")
    assert mech.design.p0[-2:] == pytest.approx([35.0, 55.0])
    design = mech.design.p0 + np.array([5.0, -4.0, 3.0, 7.0, -6.0])
    assert rest_point(mech, design) == pytest.approx([42.0, 49.0, 0.0], abs=1e-12)
    anchors = np.asarray(geometry(mech, design).anchors) * mech.length_scale
    c = anchors[mech.joint_names.index("C")]
    assert c[:2] == pytest.approx(
        mech.anchors[mech.joint_names.index("C")][:2] + [-4, 3]
    )


def test_an_undriven_coordinate_still_follows_the_anchors():
    """Only ``x`` driven: ``y`` moves as the file's affine rule moves it (the same
    as in the file without the parameter)."""
    only_x = POINT_PARAMETERS.split('[[parameters]]\nname = "tip_y"')[0]
    driven = linkopt.loads(with_parameters(only_x), str(FILE))
    plain = linkopt.load(FILE)
    change = np.array([4.0, -5.0, 6.0])
    followed = rest_point(plain, plain.design.p0 + change)
    got = rest_point(driven, np.r_[driven.design.p0[:3] + change, 31.0])
    assert got[0] == pytest.approx(31.0, abs=1e-12)
    assert got[1:] == pytest.approx(followed[1:], abs=1e-12)
    assert abs(followed[1] - 55.0) > 0.1  # the rule does move it


def test_a_written_design_reads_back_as_the_same_design(mech):
    design = mech.design.p0 + np.array([2.0, 3.0, -2.0, -7.5, 6.25])
    text = dumps(design_definition(mech, design, 0.1))
    again = linkopt.loads(text, str(FILE))
    assert again.design.names == mech.design.names
    assert again.design.p0 == pytest.approx(design, abs=1e-12)
    assert again.design.lower == pytest.approx(mech.design.lower)
    assert rest_point(again, None) == pytest.approx(rest_point(mech, design), abs=1e-12)
    moved = again.design.p0 + np.array([1.0, -1.0, 2.0, 3.0, -3.0])
    assert rest_point(again, moved)[:2] == pytest.approx(moved[-2:], abs=1e-12)


def test_bounds_and_values_are_data_not_structure(mech):
    """Other bounds (and so another initial value inside them) keep the programs."""
    other = linkopt.loads(
        with_parameters(POINT_PARAMETERS.replace("20.0", "10.0")), str(FILE)
    )
    assert structure(padded(other)) == structure(padded(mech))
    plain = linkopt.load(FILE)
    assert plain.design.points is None  # files without point parameters: unchanged


def test_point_moves_leaves_a_driven_point_unreported(mech):
    assert point_moves(mech, box_designs(mech)) == ()


def test_the_path_gradient_wrt_the_point_matches_finite_differences(mech):
    turn = np.array([0.0, 1.5, 3.0, 4.5])
    plain = linkopt.load(FILE)
    traced = plain.design.p0 + np.array([2.0, -3.0, 4.0])
    design = np.r_[traced, 38.0, 52.0]
    targets = build(
        str(FILE), "test", "path", "coupler_point",
        np.column_stack([_curve(mech, design, turn) + [0.3, -0.2], np.zeros(4)]),
        turn[:, None], False, 0.5,
    )  # fmt: skip
    problem = objective.Problem(targets, objective.plan(mech, targets, STEPS))
    from linkopt._design.evaluation import alpha_minus

    alpha = alpha_minus(mech)
    step = 1e-4
    # the design and its steps along the point's x and y in one batch: one score
    # program and one gradient program (a program per batch shape)
    e = step * np.eye(5)[[3, 4]]
    designs = np.array([design, *(design + e), *(design - e)])
    scored = objective.score(mech, problem, designs, alpha)
    assert float(scored.path[0]) > 0.0
    gradient = objective.gradients(mech, problem, designs, scored, alpha)[0]
    path = np.asarray(scored.path)
    for j, i in enumerate((3, 4)):  # the point's x and y
        up, down = path[1 + j], path[3 + j]
        assert abs(gradient[i]) > 1e-6
        assert gradient[i] == pytest.approx((up - down) / (2 * step), rel=1e-4)


def _curve(mech, design, turn) -> np.ndarray:
    """The coupler point over crank angles ``turn`` (rest branch), circle
    intersection."""
    geom = geometry(mech, design)
    scale = mech.length_scale
    anchors = np.asarray(geom.anchors)[:, :2] * scale
    a, b0, c0, d = (anchors[mech.joint_names.index(n)] for n in "ABCD")
    rest = np.stack([a, b0, c0, d, rest_point(mech, design)[:2]])
    return starts.coupler_points(rest, turn)


def test_the_starts_place_the_point_by_the_parameters(mech):
    targets = build(
        str(FILE), "test", "path", "coupler_point",
        np.column_stack([_curve(mech, mech.design.p0, np.linspace(0, 6, 6)),
                         np.zeros(6)]),
        None, True, 0.5,
    )  # fmt: skip
    frame = starts.frame_of(mech, targets)
    assert frame.rule == "driven"
    designs = np.random.default_rng(1).uniform(
        mech.design.lower, mech.design.upper, (4, mech.design.size)
    )
    fast = starts.placed_batch(mech, frame, designs)
    exact = starts.placed_batch(mech, starts.replace(frame, rule="follow"), designs)
    assert fast == pytest.approx(exact, abs=1e-12)
    assert fast[:, 4] == pytest.approx(designs[:, 3:] - frame.plane[0, :2], abs=1e-12)


@pytest.mark.parametrize(
    "edit, field, words",
    [
        ('point = "coupler_point"', 'point = "nowhere"', "unknown point 'nowhere'"),
        ('coordinate = "x"', 'coordinate = "w"', "expected one of ['x', 'y', 'z']"),
        ("min = 20.0", "min = 36.0", "rest value 35 of coupler_point.x lies outside"),
        ("max = 50.0", "max = 10.0", "bounds need min < max"),
    ],
)
def test_a_malformed_point_parameter_names_its_field(edit, field, words):
    text = with_parameters(POINT_PARAMETERS.replace(edit, field, 1))
    with pytest.raises(MechanismFileError, match=r"parameters\[3\]") as caught:
        linkopt.loads(text, str(FILE))
    assert words in str(caught.value)
    assert "\n" not in str(caught.value)


@pytest.mark.parametrize("where", ["ground", "joint"])
def test_a_point_no_parameter_can_place_is_refused(where):
    if where == "ground":
        extra = (
            '[[points]]\nname = "mark"\nbody = "ground"\nposition = [1.0, 2.0, 0.0]\n'
        )
        words = "is on the ground body"
    else:
        extra = '[[points]]\nname = "mark"\nbody = "coupler"\njoint = "B"\n'
        words = "is given by 'joint'"
    text = TEXT.replace("[[outputs]]", extra + "\n[[outputs]]", 1)
    parameter = POINT_PARAMETERS.split("[[parameters]]")[1]
    parameter = parameter.replace('"coupler_point"', '"mark"').replace("20.0", "-90.0")
    parameter = parameter.replace("50.0", "90.0")
    with pytest.raises(MechanismFileError, match=r"parameters\[3\]\.point") as caught:
        linkopt.loads(with_parameters("[[parameters]]" + parameter, text), str(FILE))
    assert words in str(caught.value)


def test_the_starts_meet_a_curve_that_needs_the_point_moved(mech):
    """Eight points of the coupler curve of a design whose coupler point lies
    elsewhere on the coupler: the best refined start (precision-point fits, the
    atlas, the point's place among the unknowns) meets them to 0.5 % of their
    extent on the closed-form curve."""
    design = np.r_[mech.design.p0[:3] + [2.0, -3.0, 4.0], 41.0, 49.0]
    goals = _curve(mech, design, np.linspace(0.0, 2 * np.pi, 8, endpoint=False))
    targets = build(str(FILE), "test", "path", "coupler_point",
                    np.column_stack([goals, np.zeros(8)]), None, True, 0.5)  # fmt: skip
    found = starts.candidates(mech, targets, seed=0, count=48)
    frame = starts.frame_of(mech, targets)
    rest = starts.placed_batch(mech, frame, found[:1])
    turn = np.linspace(-np.pi, np.pi, 3600, endpoint=False)
    curve = starts.coupler_points(rest[0], turn)
    gaps = np.linalg.norm(curve[:, None] - goals[None], axis=-1).min(axis=0)
    extent = np.linalg.norm(np.ptp(goals, axis=0))
    assert np.sqrt(np.mean(gaps**2)) < 0.005 * extent


def test_a_placed_four_bar_reads_back_as_its_design(mech):
    """``four_bar_design`` places the coupler point too where point parameters
    let it move: a design's own four-bar gives that design back."""
    from linkopt._synth.fourbar import four_bar_design, read_four_bar

    design = mech.design.p0 + np.array([1.5, -2.0, 2.5, 4.0, -3.0])
    assert four_bar_design(mech, read_four_bar(mech, design)) == pytest.approx(
        design, abs=1e-9
    )
