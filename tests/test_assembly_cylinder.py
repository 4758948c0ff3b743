"""Assembly of a hydraulic cylinder (barrel and rod on a prismatic joint) drawn roughly:
the slide takes up the drawing's errors, the axis stays on the pins, motors stay at
their drawn values (a linear motor: the drawn distance between its bodies' pins along
the axis), and a cylinder that cannot close is refused naming the prismatic joint.

``tests/data/cylinder_frames.toml`` (part drawings) and ``cylinder_world.toml`` (world
anchors): ground pins O = (0, 0) (the boom) and G = (150, -100) (the barrel), the boom
pin B 300 from O, barrel 150 and rod 123.4 along the cylinder's axis, drawn 0.3° off
the line G -> B; in world anchors the boom's length is declared. The closed form: the
cylinder lies on G -> B, so B is fixed by the motor (the boom's drawn direction, or
|GB| at the linear motor's drawn stroke with B on the boom's circle) and the slide is
|GB| - 150 - 123.4."""

import copy
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

import linkopt
from linkopt._cli.main import main
from linkopt._files.assembly import assemble, read_problem, start
from linkopt._files.assembly.solve import residual_np
from linkopt._files.fields import parse_text
from linkopt._files.loader import build
from linkopt._files.writer import dumps

DATA = Path(__file__).parent / "data"
PIVOT = np.zeros(3)
G = np.array([150.0, -100.0, 0.0])
BOOM, BARREL, ROD = 300.0, 150.0, 123.4


def drawn_axis() -> np.ndarray:
    """The cylinder's drawn axis: 0.3° off G -> B, B at 30° on the boom."""
    b = BOOM * np.array([math.cos(math.pi / 6), math.sin(math.pi / 6), 0.0])
    theta = math.atan2(b[1] - G[1], b[0] - G[0]) + math.radians(0.3)
    return np.array([math.cos(theta), math.sin(theta), 0.0])


def drawn_b(variant: str) -> np.ndarray:
    """The drawn anchor of B: the rod's eye (world), or the mean of the rod's and the
    boom's images (part drawings)."""
    eye = G + (BARREL + ROD) * drawn_axis()
    if variant == "world":
        return eye
    boom = BOOM * np.array([math.cos(math.pi / 6), math.sin(math.pi / 6), 0.0])
    return (eye + boom) / 2


def on_circles(r1: float, r2: float, side: np.ndarray) -> np.ndarray:
    """The point at ``r1`` from O and ``r2`` from G on ``side``'s side of O -> G."""
    d = np.linalg.norm(G - PIVOT)
    u = (G - PIVOT) / d
    a = (r1**2 - r2**2 + d**2) / (2 * d)
    normal = np.array([-u[1], u[0], 0.0])
    sign = np.sign(np.cross(G - PIVOT, side - PIVOT)[2])
    return PIVOT + a * u + sign * math.sqrt(r1**2 - a**2) * normal


def expected_b(variant: str, motor: str) -> np.ndarray:
    """B in closed form: a linear motor holds |GB| at its drawn stroke (B - G) · axis;
    a motor at O holds the boom along its drawn direction."""
    b = drawn_b(variant)
    if motor == "linear":
        return on_circles(BOOM, (b - G) @ drawn_axis(), b)
    return BOOM * b / np.linalg.norm(b)


def cylinder(variant: str, motor: str) -> dict:
    """The file, with its linear motor (``lift`` on the slide) or a rotary motor at O
    (the slide's displacement then the output)."""
    data = parse_text(DATA / f"cylinder_{variant}.toml")
    if motor == "rotary":
        data["motors"] = [{"name": "boom", "joint": "O"}]
        data["outputs"] = [
            {"name": "stroke", "joint": "cyl", "min": -20.0, "max": 20.0}
        ]
    return data


def anchors_of(data: dict) -> dict[str, np.ndarray]:
    return {j["name"]: np.array(j["anchor"]) for j in data["joints"]}


CASES = [(v, m) for v in ("frames", "world") for m in ("linear", "rotary")]


@pytest.mark.parametrize("variant, motor", CASES, ids=["-".join(c) for c in CASES])
def test_rough_cylinder_assembles_and_its_slide_takes_up_the_error(variant, motor):
    result = assemble(cylinder(variant, motor), f"cylinder_{variant}.toml")
    got = anchors_of(result.data)
    b = expected_b(variant, motor)
    assert np.max(np.abs(got["B"] - b)) < 1e-9
    assert np.all(got["O"] == PIVOT) and np.all(got["G"] == G)
    # the cylinder lies on its pins: its axis along G -> B, the slide's anchor on it
    axis = np.array(result.data["joints"][2]["axis"])
    along = (b - G) / np.linalg.norm(b - G)
    assert np.linalg.norm(np.cross(axis, along)) < 1e-12 and axis @ along > 0
    assert np.max(np.abs(got["cyl"] - (G + BARREL * along))) < 1e-9
    # the slide: where the rod's anchor sits from the barrel's, |GB| - 150 - 123.4
    (name, drawn, slide), *others = result.report.slides
    assert name == "cyl" and not others and abs(drawn) < 1e-9
    assert slide == pytest.approx(np.linalg.norm(b - G) - BARREL - ROD, abs=1e-9)
    assert result.report.residual < 1e-9


@pytest.mark.parametrize("motor", ["linear", "rotary"])
def test_cylinder_drawn_exactly_moves_nothing_and_does_not_slide(motor):
    """The part drawings made consistent (cylinder on G -> B, rod |GB| - 150 long):
    nothing moves and the slide stays at zero."""
    data = cylinder("frames", motor)
    b = BOOM * np.array([math.cos(math.pi / 6), math.sin(math.pi / 6), 0.0])
    along = (b - G) / np.linalg.norm(b - G)
    half = math.atan2(along[1], along[0]) / 2
    for body in data["bodies"][2:]:
        body["orientation"] = [math.cos(half), 0.0, 0.0, math.sin(half)]
    data["bodies"][3]["frame"] = list(G + BARREL * along)
    data["bodies"][3]["anchors"]["B"] = [np.linalg.norm(b - G) - BARREL, 0.0, 0.0]
    result = assemble(data, "exact.toml")
    assert result.report.largest_move < 1e-9
    assert abs(result.report.slides[0][2]) < 1e-9


@pytest.mark.parametrize("variant, motor", CASES, ids=["-".join(c) for c in CASES])
def test_assembled_cylinder_is_an_ordinary_file_that_moves(variant, motor, tmp_path):
    result = assemble(cylinder(variant, motor), "x")
    mech = build(copy.deepcopy(result.data), "assembled.toml")
    assert linkopt.mobility(mech) == mech.num_motors == 1
    rest = linkopt.solve_fk(mech, np.zeros(1))
    assert bool(rest.converged) and float(rest.residual) <= 1e-10
    value = 5.0 if motor == "linear" else 0.05
    moved = linkopt.solve_fk(mech, np.array([value]), start=rest.state)
    assert bool(moved.converged) and float(moved.residual) <= 1e-10
    assert float(linkopt.motor_values(mech, moved.state)[0]) == pytest.approx(value)
    tip = np.asarray(linkopt.point_positions(mech, moved.state))[0]
    assert abs(np.linalg.norm(tip) - BOOM) < 1e-9  # B stays on the boom's circle
    if motor == "linear":  # the stroke is the pins' distance from rest
        stroke = np.linalg.norm(tip - G) - np.linalg.norm(
            anchors_of(result.data)["B"] - G
        )
        assert stroke == pytest.approx(value, abs=1e-9)


@pytest.mark.parametrize("variant", ["frames", "world"])
def test_cli_assembles_a_cylinder_that_check_accepts(variant, tmp_path, capsys):
    out = tmp_path / "assembled.toml"
    source = DATA / f"cylinder_{variant}.toml"
    assert main(["assemble", str(source), "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    (slide,) = report["slides"]
    assert slide["joint"] == "cyl" and report["residual"] < 1e-9
    assert main(["check", str(out)]) == 0
    capsys.readouterr()
    assert np.array_equal(linkopt.load(source).anchors, linkopt.load(out).anchors)
    assert main(["assemble", str(source), "--out", str(tmp_path / "b.toml")]) == 0
    assert re.search(
        r"\n  slide cyl: drawn 0, assembled -?[0-9.e-]+ mm", capsys.readouterr().out
    )


def test_prismatic_joint_does_not_turn_about_its_axis():
    """The third axis row of the prismatic joint: turning the rod about the cylinder
    axis by φ makes it sin φ (up to sign), turning barrel and rod together leaves it
    at its drawn value, and so does turning the rod about the pins' axis z (a normal of
    the cylinder's axis: that is the parallel rows' business)."""
    problem = read_problem(cylinder("frames", "linear"), "x")
    labels = [label[2] for label in problem.row_labels]
    rows = [k for k, text in enumerate(labels) if text == "the axis of cyl"]
    assert len(rows) == 3
    sizes = (len(problem.joint_names), len(problem.frame_names))
    x0 = start(problem)
    barrel, rod = (
        3 * 4 + 6 * problem.frame_names.index(n) + 3 for n in ("barrel", "rod")
    )
    drawn = residual_np(sizes, problem.rows, x0)[rows[2]]
    for phi in (1e-3, 0.2, 0.7):
        x = x0.copy()
        x[rod : rod + 3] = phi * drawn_axis()
        twisted = residual_np(sizes, problem.rows, x)[rows[2]]
        assert abs(abs(twisted - drawn) - math.sin(phi)) < 1e-6
        x[barrel : barrel + 3] = phi * drawn_axis()
        assert abs(residual_np(sizes, problem.rows, x)[rows[2]] - drawn) < 1e-6
        x = x0.copy()
        x[rod : rod + 3] = [0.0, 0.0, phi]
        turned = residual_np(sizes, problem.rows, x)[rows]
        assert abs(turned[2] - drawn) < 1e-12 and np.max(np.abs(turned[:2])) > 0.9 * (
            math.sin(phi)
        )
    assert abs(drawn) < 1e-9


def test_cylinder_that_cannot_reach_its_pin_is_refused_naming_the_slide():
    """The rod's eye drawn 600 off its axis: the cylinder's line through G would have
    to pass 600 from B, but B (on the boom) is at most |OG| + 300 = 480 from G."""
    data = cylinder("frames", "rotary")
    data["bodies"][3]["anchors"]["B"] = [ROD, 600.0, 0.0]
    with pytest.raises(linkopt.MechanismFileError) as err:
        assemble(data, "offset.toml")
    message = str(err.value)
    assert message.startswith("offset.toml: ") and "\n" not in message
    assert (
        "the loop through joints G, cyl, B, O (bodies ground, barrel, rod, boom) "
        "does not close" in message
    )
    assert re.search(
        r"rod's anchor of cyl on the axis line of cyl \(off it by [0-9.]+ mm", message
    )
    assert "cyl has slid" in message


def test_stroke_beyond_the_boom_is_refused_naming_motor_joint_and_miss(
    tmp_path, capsys
):
    """``--motors 400`` holds the pins 673.4 apart along the axis; the boom reaches at
    most |OG| + 300 from G, so the loop misses by the difference."""
    out = tmp_path / "x.toml"
    source = DATA / "cylinder_frames.toml"
    assert main(["assemble", str(source), "--out", str(out), "--motors", "400"]) == 2
    err = capsys.readouterr().err
    assert "the loops close, but not with motor(s) 'lift' held" in err
    assert "'lift' drives joint cyl" in err and "x.toml was not written" in err
    assert "the loop through joints G, cyl, B, O" in err and "cyl has slid" in err
    # the least squares assembly splits the miss between the loop and the motor
    stroke = (drawn_b("frames") - G) @ drawn_axis() + 400.0
    reach = np.linalg.norm(G) + BOOM
    gap = float(re.search(r"misses by ([0-9.e+-]+) mm", err).group(1))
    share = float(re.search(r"and has 'lift' ([0-9.e+-]+) mm off", err).group(1))
    assert gap - share == pytest.approx(stroke - reach, rel=1e-5)
    free = float(re.search(r"'lift' ([0-9.e+-]+) mm from the value held", err).group(1))
    assert free == pytest.approx(-400.0, abs=1.0)
    assert not out.exists()


def test_cylindrical_joint_slides_too():
    """A cylindrical joint in place of the prismatic one slides alike (its two line
    rows; it may turn about its axis, which the pins' parallel axes hold here)."""
    data = cylinder("frames", "rotary")
    data["joints"][2]["type"] = "cylindrical"
    data["outputs"][0]["kind"] = "displacement"
    result = assemble(data, "cylindrical.toml")
    got = anchors_of(result.data)
    b = expected_b("frames", "rotary")
    assert np.max(np.abs(got["B"] - b)) < 1e-9
    slide = result.report.slides[0][2]
    assert slide == pytest.approx(np.linalg.norm(b - G) - BARREL - ROD, abs=1e-9)
    assert linkopt.mobility(build(result.data, "cylindrical.toml")) == 1


def test_declared_length_on_a_cylinder_body_given_by_world_anchors_must_agree():
    """A barrel given by world anchors is read as its drawing (rigid): its drawn length
    may be declared, a different one is a one-line error naming the length."""
    data = cylinder("world", "linear")
    data["lengths"].append({"joints": ["G", "cyl"], "length": BARREL})
    assert assemble(copy.deepcopy(data), "agree.toml").report.residual < 1e-9
    data["lengths"][-1]["length"] = 149.0
    with pytest.raises(linkopt.MechanismFileError) as err:
        assemble(data, "rigid.toml")
    message = str(err.value)
    assert message.startswith(
        "rigid.toml: lengths[1]: G and cyl are both on body 'barrel', which carries "
        "the axis of a prismatic or cylindrical joint and so is rigid as drawn"
    )
    assert "declared 149" in message and "\n" not in message


@pytest.mark.parametrize("variant", ["frames", "world"])
def test_motors_extend_the_cylinder_from_its_drawn_stroke(variant):
    """``motors = [12]``: the pins end 12 further apart along the axis than drawn, B on
    the boom's circle, and the slide takes the parts' error as before."""
    result = assemble(cylinder(variant, "linear"), "x", motors=[12.0])
    b = drawn_b(variant)
    expected = on_circles(BOOM, (b - G) @ drawn_axis() + 12.0, b)
    got = anchors_of(result.data)["B"]
    assert np.max(np.abs(got - expected)) < 1e-9
    slide = result.report.slides[0][2]
    assert slide == pytest.approx(np.linalg.norm(got - G) - BARREL - ROD, abs=1e-9)


#: The excavator's cylinders: (joint, barrel, rod, pivot joint, eye joint).
CYLINDERS = (
    ("lift", "barrel1", "rod1", "G1", "B1"),
    ("crowd", "barrel2", "rod2", "C2", "B2"),
)


def quaternion_x(q) -> np.ndarray:
    """The body's x axis in the world for the quaternion ``[w, 0, 0, z]``."""
    t = 2 * math.atan2(q[3], q[0])
    return np.array([math.cos(t), math.sin(t), 0.0])


def angle_at(centre, a, b) -> float:
    u, v = a - centre, b - centre
    return math.atan2(np.cross(u, v)[2], u @ v)


@pytest.mark.parametrize("motors", ["linear", "rotary"])
def test_two_cylinder_excavator_drawn_roughly_assembles(motors, tmp_path, capsys):
    """``tests/data/excavator_drawn.toml``: two loops, boom and stick each driven by a
    cylinder drawn a few hundredths of a degree off with its rod tenths of a mm long.
    Linear motors keep the drawn strokes (pin distance along the drawn axis); rotary
    motors at O and S keep the boom's drawn direction and the stick's drawn angle on
    the boom. Each cylinder ends on its pins, and its slide is the pins' distance less
    barrel and rod."""
    data = parse_text(DATA / "excavator_drawn.toml")
    if motors == "rotary":
        data["motors"] = [
            {"name": "boom", "joint": "O"},
            {"name": "stick", "joint": "S"},
        ]
        data["outputs"] = [
            {"name": name, "joint": name, "min": -5.0, "max": 5.0}
            for name in ("lift", "crowd")
        ]
    drawn = anchors_of_problem(data)
    result = assemble(copy.deepcopy(data), "excavator.toml")
    got = anchors_of(result.data)
    bodies = {b["name"]: b for b in data["bodies"]}
    slides = {name: s for name, _, s in result.report.slides}
    for joint, barrel, rod, pivot, eye in CYLINDERS:
        along = got[eye] - got[pivot]
        axis = next(j["axis"] for j in result.data["joints"] if j["name"] == joint)
        assert np.linalg.norm(np.cross(axis, along / np.linalg.norm(along))) < 1e-12
        length = bodies[barrel]["anchors"][joint][0] + bodies[rod]["anchors"][eye][0]
        assert slides[joint] == pytest.approx(np.linalg.norm(along) - length, abs=1e-9)
        if motors == "linear":
            stroke = (drawn[eye] - drawn[pivot]) @ quaternion_x(
                bodies[barrel]["orientation"]
            )
            assert np.linalg.norm(along) == pytest.approx(stroke, abs=1e-9)
    if motors == "rotary":
        s, o = got["S"], got["O"]
        assert np.linalg.norm(np.cross(s / np.linalg.norm(s), drawn["S"])) < 1e-12
        assert angle_at(s, o, got["B2"]) == pytest.approx(
            angle_at(drawn["S"], drawn["O"], drawn["B2"]), abs=1e-12
        )
    assert result.report.residual < 1e-9
    out = tmp_path / "excavator.toml"
    out.write_text(dumps(result.data))
    assert main(["check", str(out)]) == 0
    assert "mobility           2" in capsys.readouterr().out


def anchors_of_problem(data: dict) -> dict[str, np.ndarray]:
    """The drawn anchors, as assembly reads them (frames resolved)."""
    problem = read_problem(copy.deepcopy(data), "x")
    return dict(zip(problem.joint_names, problem.drawn))
