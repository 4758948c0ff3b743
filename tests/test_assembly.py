"""Assembly from approximate anchors and declared dimensions (``[[lengths]]``, bodies
in their own frame): declared dimensions held exactly, the drawing's branch kept,
closed forms (circle and three-sphere intersections), least movement, the five-bar
rebuilt from its lengths, loops that cannot close, bad fields, ``linkopt assemble``."""

import copy
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest
from conftest import MECHANISMS
from five_bar_closed_form import forward as five_bar_forward
from scipy.optimize import minimize_scalar

import linkopt
from linkopt._cli.main import main
from linkopt._files.assembly import assemble
from linkopt._files.fields import parse_text, parse_toml
from linkopt._files.loader import build, loads

DATA = Path(__file__).parent / "data"
FOUR_BAR = """
[mechanism]
name = "four-bar"
ground = "ground"
units = "mm"
assemble = true
[[bodies]]
name = "ground"
[[bodies]]
name = "crank"
[[bodies]]
name = "coupler"
[[bodies]]
name = "rocker"
[[joints]]
name = "a"
type = "revolute"
bodies = ["ground", "crank"]
anchor = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "b"
type = "revolute"
bodies = ["crank", "coupler"]
anchor = [{b}]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "c"
type = "revolute"
bodies = ["coupler", "rocker"]
anchor = [{c}]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "d"
type = "revolute"
bodies = ["rocker", "ground"]
anchor = [40.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[lengths]]
joints = ["a", "b"]
length = {crank}
[[lengths]]
joints = ["b", "c"]
length = {coupler}
[[lengths]]
joints = ["c", "d"]
length = {rocker}
[[motors]]
name = "crank"
joint = "a"
[[points]]
name = "p"
body = "coupler"
position = [20.0, 30.0, 0.0]
[[outputs]]
name = "rocker"
joint = "d"
min = 0.0
max = 3.0
"""
UP = {"b": "8.0, 13.0, 0.0", "c": "38.0, 35.0, 0.0"}
DOWN = {"b": "8.0, 13.0, 0.0", "c": "30.0, -25.0, 0.0"}
SIZES = {"crank": 15.0, "coupler": 40.0, "rocker": 35.0}
#: The crank drawn 1e-3 rad short of π.
TOGGLE = f"{-15 * math.cos(1e-3)!r}, {15 * math.sin(1e-3)!r}, 0.0"


def four_bar(**fields) -> str:
    return FOUR_BAR.format(**(UP | SIZES | fields))


def anchors_of(data: dict) -> dict[str, np.ndarray]:
    return {j["name"]: np.array(j["anchor"]) for j in data["joints"]}


def circle_intersection(p, r1, q, r2, side) -> np.ndarray:
    """The point at ``r1`` from ``p`` and ``r2`` from ``q`` (plane z = 0) on the side
    of the line ``p → q`` that ``side`` is on."""
    d = np.linalg.norm(q - p)
    u = (q - p) / d
    a = (r1**2 - r2**2 + d**2) / (2 * d)
    h = math.sqrt(r1**2 - a**2)
    normal = np.array([-u[1], u[0], 0.0])
    sign = np.sign(np.cross(q - p, side - p)[2])
    return p + a * u + sign * h * normal


@pytest.mark.parametrize("drawing", [UP, DOWN], ids=["elbow_up", "elbow_down"])
def test_four_bar_holds_lengths_and_the_drawn_branch(drawing):
    data = parse_toml(four_bar(**drawing), "four_bar.toml")
    got = anchors_of(assemble(data, "four_bar.toml").data)
    drawn = anchors_of(data)
    for (i, j), length in zip(("ab", "bc", "cd"), SIZES.values()):
        assert abs(np.linalg.norm(got[i] - got[j]) - length) < 1e-12
    # the crank motor is held at its drawn angle: b is on the drawn ray
    ray = drawn["b"] / np.linalg.norm(drawn["b"])
    assert np.max(np.abs(got["b"] - 15.0 * ray)) < 1e-12
    expected = circle_intersection(got["b"], 40.0, got["d"], 35.0, drawn["c"])
    assert np.max(np.abs(got["c"] - expected)) < 1e-12
    side = np.cross(got["d"] - got["b"], got["c"] - got["b"])[2]
    assert np.sign(side) == np.sign(
        np.cross(drawn["d"] - drawn["b"], drawn["c"] - drawn["b"])[2]
    )
    assert np.all(got["a"] == 0.0) and np.all(got["d"] == [40.0, 0.0, 0.0])


def test_free_crank_moves_the_anchors_least():
    """Without a motor the assembly is a one-parameter family (the crank angle φ); the
    one returned is the nearest to the drawing, found here by a scalar search."""
    text = four_bar().replace('[[motors]]\nname = "crank"\njoint = "a"\n', "")
    data = parse_toml(text, "x")
    drawn = anchors_of(data)
    got = anchors_of(assemble(data, "x").data)

    def family(phi):
        b = 15.0 * np.array([math.cos(phi), math.sin(phi), 0.0])
        return b, circle_intersection(b, 40.0, drawn["d"], 35.0, drawn["c"])

    def movement(phi):
        b, c = family(phi)
        return np.sum((b - drawn["b"]) ** 2) + np.sum((c - drawn["c"]) ** 2)

    best = minimize_scalar(
        movement, bounds=(0.5, 1.5), method="bounded", options={"xatol": 1e-12}
    )
    b, c = family(best.x)
    assert np.max(np.abs(got["b"] - b)) < 1e-6 and np.max(np.abs(got["c"] - c)) < 1e-6
    moved = np.sum((got["b"] - drawn["b"]) ** 2) + np.sum((got["c"] - drawn["c"]) ** 2)
    assert moved <= best.fun + 1e-12


def test_coupler_in_its_own_frame_keeps_its_shape_and_point():
    """The coupler given in a turned frame: its anchors and the coupler point move as
    one rigid body, and its length is the local one exactly."""
    quarter = [math.cos(0.15), 0.0, 0.0, math.sin(0.15)]
    text = four_bar().replace(
        'name = "coupler"\n',
        'name = "coupler"\nframe = [24.0, 23.0, 0.0]\n'
        f"orientation = {quarter}\n"
        "anchors = { b = [-20.0, -5.0, 0.0], c = [20.0, -5.0, 0.0] }\n",
        1,
    )
    text = text.replace("anchor = [8.0, 13.0, 0.0]\n", "").replace(
        "anchor = [38.0, 35.0, 0.0]\n", ""
    )
    text = text.replace('[[lengths]]\njoints = ["b", "c"]\nlength = 40.0\n', "")
    # the coupler point is given in the coupler frame, as its anchors are
    local = np.array([-3.0, 8.0])
    text = text.replace(
        "position = [20.0, 30.0, 0.0]", f"position = [{local[0]}, {local[1]}, 0.0]"
    )
    data = parse_toml(text, "x")
    result = assemble(data, "x")
    got = anchors_of(result.data)
    assert abs(np.linalg.norm(got["b"] - got["c"]) - 40.0) < 1e-12
    assert abs(np.linalg.norm(got["a"] - got["b"]) - 15.0) < 1e-12
    assert abs(np.linalg.norm(got["c"] - got["d"]) - 35.0) < 1e-12
    point = np.array(result.data["points"][0]["position"])
    for joint, at in (("b", [-20.0, -5.0]), ("c", [20.0, -5.0])):
        assert (
            abs(np.linalg.norm(point - got[joint]) - np.linalg.norm(local - at)) < 1e-12
        )
    coupler = result.data["bodies"][2]
    assert set(coupler) == {"name", "origin"}
    mech = build(result.data, "x")  # an ordinary file now
    assert mech.num_motors == 1


SLIDER_CRANK = """
[mechanism]
name = "slider-crank"
ground = "ground"
assemble = true
[[bodies]]
name = "ground"
[[bodies]]
name = "crank"
[[bodies]]
name = "rod"
[[bodies]]
name = "slider"
frame = [59.0, 10.0, 0.0]
anchors = { C = [0.0, 0.0, 0.0], slide = [0.0, 0.0, 0.0] }
[[joints]]
name = "O"
type = "revolute"
bodies = ["ground", "crank"]
anchor = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "B"
type = "revolute"
bodies = ["crank", "rod"]
anchor = [1.0, 19.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "C"
type = "revolute"
bodies = ["rod", "slider"]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "slide"
type = "prismatic"
bodies = ["ground", "slider"]
anchor = [59.0, 10.0, 0.0]
axis = [1.0, 0.0, 0.0]
[[lengths]]
joints = ["O", "B"]
length = 20.0
[[lengths]]
joints = ["B", "C"]
length = 60.0
[[motors]]
name = "slide"
joint = "slide"
[[outputs]]
name = "crank_angle"
joint = "O"
min = -0.8
max = 0.8
"""


def test_slider_on_its_rail_places_the_crank_pin():
    """A linear motor: the slider (in its own frame, its pin on the rail) stays where
    its ground-side anchor is written; the crank pin is the circle intersection."""
    result = assemble(parse_toml(SLIDER_CRANK, "x"), "x")
    got = anchors_of(result.data)
    assert np.max(np.abs(got["C"] - [59.0, 10.0, 0.0])) < 1e-12
    expected = circle_intersection(
        got["O"], 20.0, got["C"], 60.0, np.array([1.0, 19.0, 0])
    )
    assert np.max(np.abs(got["B"] - expected)) < 1e-12
    assert build(result.data, "x").num_motors == 1


def trilaterate(p1, p2, p3, l1, l2, l3, side) -> np.ndarray:
    """The point at distances ``l1, l2, l3`` from ``p1, p2, p3`` on ``side``'s side of
    their plane (three-sphere intersection)."""
    d = np.linalg.norm(p2 - p1)
    ex = (p2 - p1) / d
    i = ex @ (p3 - p1)
    ey = p3 - p1 - i * ex
    j = np.linalg.norm(ey)
    ey /= j
    ez = np.cross(ex, ey)
    x = (l1**2 - l2**2 + d**2) / (2 * d)
    y = (l1**2 - l3**2 + i**2 + j**2) / (2 * j) - i * x / j
    z = math.sqrt(l1**2 - x**2 - y**2)
    z = z if ez @ (side - p1) > 0 else -z
    return p1 + x * ex + y * ey + z * ez


TRIPOD_BASE = np.array([[30.0, 0.0, 0.0], [-12.0, 25.0, 0.0], [-14.0, -22.0, 3.0]])
TRIPOD_RODS = (41.0, 37.5, 44.0)


def tripod(apex: str) -> str:
    """Three rods between ball joints on the ground and a common apex body, given in
    its own frame (its three joints at its origin)."""
    text = '[mechanism]\nname = "tripod"\nground = "ground"\nassemble = true\n'
    text += '[[bodies]]\nname = "ground"\n'
    text += "".join(f'[[bodies]]\nname = "rod{k}"\n' for k in range(3))
    text += (
        f'[[bodies]]\nname = "apex"\nframe = [{apex}]\n'
        "orientation = [0.9, 0.1, -0.3, 0.2]\n"
        "anchors = { top0 = [0.0, 0.0, 0.0], top1 = [0.0, 0.0, 0.0], "
        "top2 = [0.0, 0.0, 0.0] }\n"
    )
    for k in range(3):
        base = ", ".join(repr(float(v)) for v in TRIPOD_BASE[k])
        text += (
            f'[[joints]]\nname = "base{k}"\ntype = "spherical"\n'
            f'bodies = ["ground", "rod{k}"]\nanchor = [{base}]\n'
            f'[[joints]]\nname = "top{k}"\ntype = "spherical"\n'
            f'bodies = ["rod{k}", "apex"]\n'
            f'[[lengths]]\njoints = ["base{k}", "top{k}"]\n'
            f"length = {TRIPOD_RODS[k]}\n"
        )
    return text


@pytest.mark.parametrize("apex", ["2.0, 1.0, 30.0", "0.0, 3.0, -28.0"])
def test_tripod_apex_is_the_three_sphere_intersection(apex):
    data = parse_toml(tripod(apex), "tripod.toml")
    result = assemble(data, "tripod.toml")
    got = anchors_of(result.data)
    side = np.array([float(v) for v in apex.split(",")])
    expected = trilaterate(*TRIPOD_BASE, *TRIPOD_RODS, side)
    for k in range(3):
        assert np.max(np.abs(got[f"top{k}"] - expected)) < 1e-12
        assert np.all(got[f"base{k}"] == TRIPOD_BASE[k])
    assert (
        np.max(np.abs(np.array(result.data["bodies"][4]["origin"]) - expected)) < 1e-12
    )
    moved = {m.joint: m.distance for m in result.report.moves}
    assert moved["top0"] == pytest.approx(np.linalg.norm(expected - side), abs=1e-12)


def test_delta_from_part_drawings_hangs_its_platform_level():
    """``tests/data/delta_lengths.toml``: arms and platform in their own frames, rods by
    length, the platform drawn 2.5 mm too high. The arms turn only about their
    shoulder axes and are held by their motors, so they stay horizontal; the platform
    hangs level at z = -sqrt(180² - 110²), each wrist 180 from its elbow."""
    data = parse_text(DATA / "delta_lengths.toml")
    result = assemble(data, "delta_lengths.toml")
    got = anchors_of(result.data)
    z = -math.sqrt(180.0**2 - 110.0**2)
    for k, angle in zip("123", np.radians([0.0, 120.0, 240.0])):
        c, s = math.cos(angle), math.sin(angle)
        turn = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
        for side, offset in (("a", 10.0), ("b", -10.0)):
            elbow = turn @ [140.0, offset, 0.0]
            wrist = turn @ [30.0, offset, 0.0] + [0.0, 0.0, z]
            assert np.max(np.abs(got[f"elbow{k}{side}"] - elbow)) < 1e-12
            assert np.max(np.abs(got[f"wrist{k}{side}"] - wrist)) < 1e-12
    tcp = np.array(result.data["points"][0]["position"])
    assert np.max(np.abs(tcp - [0.0, 0.0, z])) < 1e-12
    assert result.report.largest_move == pytest.approx(-140.0 - z, abs=1e-12)


def five_bar_by_lengths() -> dict:
    """``mechanisms/five_bar.toml`` drawn loosely: elbows 5 % too far out along the
    cranks, the tip off the symmetry axis, and the four link lengths declared."""
    data = parse_text(MECHANISMS / "five_bar.toml")
    data["mechanism"]["assemble"] = True
    exact = anchors_of(copy.deepcopy(data))
    joints = {j["name"]: j for j in data["joints"]}
    for side in ("left", "right"):
        base, elbow = exact[f"base_{side}"], exact[f"elbow_{side}"]
        joints[f"elbow_{side}"]["anchor"] = list(base + 1.05 * (elbow - base))
    joints["tip"]["anchor"] = [0.7, 67.5, 0.0]
    data["lengths"] = [
        {"joints": [f"base_{s}", f"elbow_{s}"], "length": math.sqrt(17**2 + 36**2)}
        for s in ("left", "right")
    ] + [
        {"joints": [f"elbow_{s}", "tip"], "length": math.sqrt(37**2 + 34**2)}
        for s in ("left", "right")
    ]
    return data


def test_five_bar_from_its_lengths_is_the_shipped_five_bar(five_bar):
    mech = build(five_bar_by_lengths(), "five_bar_lengths.toml")
    assert np.max(np.abs(mech.anchors - five_bar.anchors)) < 1e-12
    assert mech.length_scale == pytest.approx(five_bar.length_scale, abs=1e-12)
    assert mech.design.size == 3  # the mirror ties still hold
    motors = np.array([0.2, -0.1])
    ours = linkopt.solve_fk(mech, motors, start=linkopt.rest_state(mech))
    assert bool(ours.converged)
    tip = np.asarray(linkopt.point_positions(mech, ours.state))[0]
    assert np.max(np.abs(tip[:2] - five_bar_forward(motors)[0])) < 1e-9


def gap_of(message: str) -> float:
    return float(re.search(r"misses by ([0-9.e+-]+)", message).group(1))


def test_coupler_longer_than_the_other_links_is_refused_with_its_gap():
    text = four_bar(coupler=100.0)
    with pytest.raises(linkopt.MechanismFileError) as err:
        loads(text, "long.toml")
    message = str(err.value)
    assert (
        "long.toml: lengths[0]: the loop through joints a, b, c, d (bodies ground, "
        "crank, coupler, rocker) does not close" in message
    )
    assert "a–b = 15; b–c = 100; c–d = 35 cannot all hold" in message
    assert "the axes of a, b, c, d are held as written" in message
    # pulled straight, the chain a-b-c-d misses by 100 - (15 + 35 + 40) mm
    assert gap_of(message) == pytest.approx(10.0, rel=1e-6)


def test_triangle_violating_the_inequality_is_refused_with_its_gap():
    text = four_bar(crank=3.0, coupler=4.0).replace(
        'bodies = ["coupler", "rocker"]', 'bodies = ["coupler", "ground"]'
    )
    text = text.replace('[[lengths]]\njoints = ["c", "d"]\nlength = 35.0\n', "")
    text = text.replace("anchor = [38.0, 35.0, 0.0]", "anchor = [10.0, 0.0, 0.0]")
    data = parse_toml(text, "triangle.toml")
    with pytest.raises(linkopt.MechanismFileError) as err:
        assemble(data, "triangle.toml")
    message = str(err.value)
    assert (
        "joints a, b, c (bodies ground, crank, coupler) does not close: a–b = 3; "
        "b–c = 4 cannot all hold" in message
    )
    assert gap_of(message) == pytest.approx(3.0, rel=1e-6)


def test_loop_that_closes_only_with_the_motor_free_names_the_motors():
    """A non-Grashof four-bar (crank 30, coupler 20, rocker 15, ground 40) drawn with
    its crank pointing away from the rocker, where it cannot assemble."""
    text = four_bar(crank=30.0, coupler=20.0, rocker=15.0, b="-29.0, 3.0, 0.0")
    with pytest.raises(linkopt.MechanismFileError) as err:
        assemble(parse_toml(text, "x"), "x")
    assert "x: [[motors]]: the loops close, but not with motor(s) 'crank' held" in str(
        err.value
    )


FRAME = "frame = [1.0, 2.0, 0.0]"
COUPLER = "anchors = { b = [0.0, 0.0, 0.0], c = [30.0, 22.0, 0.0] }"


def with_body(text: str, body: str, *lines: str) -> str:
    """``text`` with ``lines`` added to the table of body ``body``."""
    name = f'name = "{body}"\n'
    return text.replace(name, name + "".join(line + "\n" for line in lines), 1)


@pytest.mark.parametrize(
    "edit, words",
    [
        (
            lambda t: t.replace('joints = ["a", "b"]', 'joints = ["a", "zz"]'),
            "lengths[0].joints: unknown joint 'zz'",
        ),
        (
            lambda t: t.replace('joints = ["a", "b"]', 'joints = ["a", "a"]'),
            "lengths[0].joints: expected two different joints",
        ),
        (
            lambda t: t.replace("length = 15.0", "length = -15.0"),
            "lengths[0].length: expected a positive number, got -15.0",
        ),
        (
            lambda t: t.replace("length = 15.0", "length = 15.0\nunit = 1"),
            "lengths[0].unit: unknown field",
        ),
        (
            lambda t: t.replace('joints = ["b", "c"]', 'joints = ["b", "a"]'),
            "lengths[1].joints: the distance b–a is already declared by lengths[0]",
        ),
        (
            lambda t: t.replace("assemble = true", "assemble = 1"),
            "[mechanism].assemble: expected true or false, got 1",
        ),
        (
            lambda t: with_body(t, "coupler", "frame = [1.0, 2.0, 0.0]"),
            "bodies[2].anchors: missing; a body in its own frame needs frame and "
            "anchors",
        ),
        (
            lambda t: with_body(
                t, "coupler", FRAME, "anchors = { b = [0.0, 0.0, 0.0] }"
            ),
            "bodies[2].anchors: missing joint 'c'",
        ),
        (
            lambda t: with_body(
                t, "coupler", FRAME, "anchors = { a = [0.0, 0.0, 0.0] }"
            ),
            "bodies[2].anchors: joint 'a' does not touch body 'coupler'",
        ),
        (
            lambda t: with_body(t, "ground", FRAME, "anchors = {}"),
            "bodies[0]: the ground is the world frame",
        ),
        (
            lambda t: with_body(
                t, "coupler", FRAME, "orientation = [0.0, 0.0, 0.0, 0.0]", COUPLER
            ),
            "bodies[2].orientation: expected a quaternion [w, x, y, z]",
        ),
        (
            lambda t: t.replace("anchor = [38.0, 35.0, 0.0]\n", ""),
            "joints[2].anchor: missing required field",
        ),
        (
            lambda t: with_body(
                t, "coupler", FRAME, COUPLER, "axes = { a = [0, 0, 1] }"
            ),
            "bodies[2].axes: joint 'a' does not touch body 'coupler'",
        ),
        (
            lambda t: with_body(
                t, "coupler", FRAME, COUPLER, "axes = { b = [0, 0, 0] }"
            ),
            "bodies[2].axes.b: zero-length axis",
        ),
        (
            lambda t: with_body(t, "coupler", FRAME, COUPLER, "axes = [0, 0, 1]"),
            "bodies[2].axes: expected a table of joint name = [x, y, z]",
        ),
        (
            lambda t: with_body(
                t.replace(
                    'type = "revolute"\nbodies = ["coupler", "rocker"]',
                    'type = "spherical"\nbodies = ["coupler", "rocker"]',
                ),
                "coupler",
                FRAME,
                COUPLER,
                "axes = { c = [0, 0, 1] }",
            ),
            "bodies[2].axes: joint 'c' is 'spherical': it has no axis",
        ),
        (
            lambda t: t.replace("assemble = true\n", ""),
            "lengths[0]: the anchors are 15.2643375225 mm apart, declared 15: fix "
            "the anchors, or set [mechanism].assemble = true",
        ),
    ],
)
def test_bad_assembly_fields_are_one_line_errors(edit, words):
    with pytest.raises(linkopt.MechanismFileError) as err:
        loads(edit(four_bar()), "bad.toml")
    message = str(err.value)
    assert message.startswith("bad.toml: ") and words in message and "\n" not in message


def test_joint_placed_by_two_frames_and_an_anchor_is_refused():
    crank = "anchors = { a = [0.0, 0.0, 0.0], b = [8.0, 13.0, 0.0] }"
    text = with_body(four_bar(), "crank", "frame = [0.0, 0.0, 0.0]", crank)
    text = with_body(text, "coupler", "frame = [8.0, 13.0, 0.0]", COUPLER)
    with pytest.raises(
        linkopt.MechanismFileError,
        match=r"joints\[1\]\.anchor: joint 'b' is placed by the frames of both",
    ):
        loads(text, "twice.toml")


def test_axis_given_by_both_frames_and_in_joints_is_refused():
    """An axis both bodies carry in their ``axes`` is given twice when ``[[joints]]``
    also has it; with one carrier's ``axes`` only, the other needs ``[[joints]]``."""
    crank = "anchors = { a = [0.0, 0.0, 0.0], b = [8.0, 13.0, 0.0] }"
    text = with_body(four_bar(), "crank", "frame = [0.0, 0.0, 0.0]", crank)
    text = with_body(text, "coupler", "frame = [8.0, 13.0, 0.0]", COUPLER)
    both = with_body(text, "crank", "axes = { b = [0.0, 0.0, 1.0] }")
    both = with_body(both, "coupler", "axes = { b = [0.0, 0.0, 1.0] }")
    both = both.replace("anchor = [8.0, 13.0, 0.0]\n", "")
    with pytest.raises(
        linkopt.MechanismFileError,
        match=r"joints\[1\]\.axis: the axis of joint 'b' is given in the axes of the "
        "body frames that carry it; give it once",
    ):
        loads(both, "twice.toml")
    one = with_body(text, "coupler", "axes = { b = [0.0, 0.0, 1.0] }")
    one = one.replace("anchor = [8.0, 13.0, 0.0]\naxis = [0.0, 0.0, 1.0]\n", "")
    with pytest.raises(
        linkopt.MechanismFileError,
        match=r"joints\[1\]\.axis: missing: a body that carries the axis of 'b'",
    ):
        loads(one, "once.toml")


def test_hand_solved_file_may_state_its_lengths(five_bar):
    data = five_bar_by_lengths()
    del data["mechanism"]["assemble"]
    exact = parse_text(MECHANISMS / "five_bar.toml")
    data["joints"] = exact["joints"]
    mech = build(data, "stated.toml")
    assert np.array_equal(mech.anchors, five_bar.anchors) and "lengths" not in mech.raw


def test_cli_writes_a_file_check_accepts_and_the_loader_reads_alike(tmp_path, capsys):
    drawing, out = tmp_path / "drawn.toml", tmp_path / "assembled.toml"
    drawing.write_text("# A four-bar, drawn.\n" + four_bar())
    assert main(["assemble", str(drawing), "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    moves = {m["joint"]: m for m in report["moves"]}
    assert set(moves) == {"a", "b", "c", "d"} and moves["a"]["distance"] == 0.0
    for m in moves.values():
        step = np.linalg.norm(np.subtract(m["after"], m["before"]))
        assert m["distance"] == pytest.approx(step, abs=1e-12)
    assert report["largest_move"] == max(m["distance"] for m in moves.values()) > 1.0
    assert all(abs(x["assembled"] - x["declared"]) < 1e-12 for x in report["lengths"])
    assert not report["near_singular"] and report["sigma_min_fk"] > 1e-2
    text = out.read_text()
    assert text.startswith("# A four-bar, drawn.\n# Assembled by `linkopt assemble`")
    assert "[[lengths]]" not in text and "assemble" not in text.split("\n\n", 1)[1]
    assert main(["check", str(out)]) == 0
    capsys.readouterr()
    on_request, written = linkopt.load(drawing), linkopt.load(out)
    assert np.array_equal(on_request.anchors, written.anchors)
    assert np.array_equal(on_request.point_positions, written.point_positions)
    assert main(["assemble", str(drawing), "--out", str(tmp_path / "b.toml")]) == 0
    table = capsys.readouterr().out
    assert re.search(
        r"\n  c +\(38, 35, 0\) +\(41\.1309, 34\.9817, 0\) +3\.13096\n", table
    )


def test_cli_warns_near_a_singularity(tmp_path, capsys):
    """Coupler 30 + rocker 25 = |b - d| with the crank at π: drawn 1e-3 rad short of
    that, the rest pose is near the forward singularity."""
    drawing = tmp_path / "toggle.toml"
    drawing.write_text(
        four_bar(coupler=30.0, rocker=25.0, b=TOGGLE, c="14.0, 1.0, 0.0")
    )
    out = tmp_path / "out.toml"
    assert main(["assemble", str(drawing), "--out", str(out), "--json"]) == 0
    captured = capsys.readouterr()
    report = json.loads(captured.out)
    assert report["near_singular"] and 1e-5 < report["sigma_min_fk"] < 1e-3
    assert (
        "linkopt: warning: the assembled rest pose is near a forward singularity"
        in (captured.err)
    )


def test_motors_turn_from_the_drawing():
    """``motors`` turns the crank from its drawn angle before assembling: b lies on the
    turned ray, and c is the circle intersection on the drawn side."""
    data = parse_toml(four_bar(), "x")
    got = anchors_of(assemble(data, "x", motors=[0.3]).data)
    turned = math.atan2(13.0, 8.0) + 0.3
    ray = np.array([math.cos(turned), math.sin(turned), 0.0])
    assert np.max(np.abs(got["b"] - 15.0 * ray)) < 1e-12
    drawn_c = np.array([38.0, 35.0, 0.0])
    expected = circle_intersection(got["b"], 40.0, got["d"], 35.0, drawn_c)
    assert np.max(np.abs(got["c"] - expected)) < 1e-12


def test_cli_refuses_bad_arguments(tmp_path, capsys):
    drawing = tmp_path / "drawn.toml"
    drawing.write_text(four_bar())
    assert main(["assemble", str(drawing), "--out", str(drawing)]) == 2
    assert "--out:" in capsys.readouterr().err
    assert (
        main(
            [
                "assemble",
                str(drawing),
                "--out",
                str(tmp_path / "x.toml"),
                "--motors",
                "1,2",
            ]
        )
        == 2
    )
    assert "--motors: expected 1 finite numbers (crank)" in capsys.readouterr().err
    assert main(["assemble", str(drawing), "--out", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err
    assert not (tmp_path / "x.toml").exists()


def test_cli_out_in_a_missing_folder_is_made_and_a_failure_writes_nothing(
    tmp_path, capsys
):
    """--out in a folder that does not exist is made, as export/animate/optimize do;
    a drawing whose loops do not close names the file it did not write and leaves no
    folder behind."""
    drawing = tmp_path / "drawn.toml"
    drawing.write_text(four_bar())
    out = tmp_path / "new" / "deeper" / "x.toml"
    assert main(["assemble", str(drawing), "--out", str(out)]) == 0
    assert linkopt.load(out).num_motors == 1
    capsys.readouterr()
    drawing.write_text(four_bar(coupler=100.0))
    failed = tmp_path / "other" / "y.toml"
    assert main(["assemble", str(drawing), "--out", str(failed)]) == 2
    err = capsys.readouterr().err
    assert "does not close" in err and f"({failed} was not written)" in err
    assert not failed.parent.exists()
