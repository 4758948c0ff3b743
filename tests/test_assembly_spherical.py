"""Spatial loops assembled from a rough drawing (issue 27, part 2): a spherical five-bar
(every joint axis through one centre) given as part drawings, its tip drawn a few
degrees off, assembles; the moving bodies carry their axes, so the written file is
consistent, passes ``linkopt check``, and its FK is the spherical five-bar's closed
form. A loop that cannot close names its joints, its bodies and its gap."""

import math
import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

import linkopt
from linkopt._cli.main import main
from linkopt._files.assembly import assemble
from linkopt._files.fields import parse_toml
from linkopt._files.writer import dumps

CENTRE = np.array([10.0, -5.0, 20.0])
RADIUS = 50.0
#: Arcs (deg) of the ground (A-E) and of the links A-B, B-C, C-D, D-E.
GROUND, ARCS = 60.0, (50.0, 70.0, 70.0, 50.0)
#: The tip drawn off: link2 turned about B's axis, link3 about D's (deg).
OFF = (4.0, -3.0)


def turn(axis, angle: float) -> np.ndarray:
    return Rotation.from_rotvec(np.radians(angle) * np.asarray(axis)).as_matrix()


def ground_axes() -> tuple[np.ndarray, np.ndarray]:
    half = math.radians(GROUND / 2)
    return np.array([-math.sin(half), 0, math.cos(half)]), np.array(
        [math.sin(half), 0, math.cos(half)]
    )


def tip(b: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Closed form: the unit axis at arc ``ARCS[1]`` from ``b`` and ``ARCS[2]`` from
    ``d``, on the side of ``b × d`` (away from the ground axes)."""
    g = b @ d
    rhs = np.cos(np.radians(ARCS[1:3]))
    u, v = np.linalg.solve([[1.0, g], [g, 1.0]], rhs)
    m = u * b + v * d
    normal = np.cross(b, d)
    return m + math.sqrt(1.0 - m @ m) / np.linalg.norm(normal) * normal


def rest_axes(arcs=ARCS) -> dict[str, np.ndarray]:
    """Axes of A..E at rest: the cranks tilted towards +y from the ground axes."""
    a, e = ground_axes()
    y = np.array([0.0, 1.0, 0.0])
    cos, sin = np.cos(np.radians(arcs)), np.sin(np.radians(arcs))
    b, d = cos[0] * a + sin[0] * y, cos[3] * e + sin[3] * y
    return {"A": a, "B": b, "C": tip(b, d), "D": d, "E": e}


def frame_to(first: np.ndarray, second: np.ndarray, arc: float) -> np.ndarray:
    """The rotation taking a link's local axes ``z`` and ``(sin arc, 0, cos arc)`` onto
    ``first`` and ``second``."""

    def basis(u, v):
        w = v - (v @ u) * u
        w /= np.linalg.norm(w)
        return np.column_stack([u, w, np.cross(u, w)])

    local = basis(np.array([0.0, 0.0, 1.0]), local_axis(arc))
    return basis(first, second) @ local.T


def local_axis(arc: float) -> np.ndarray:
    return np.array([math.sin(math.radians(arc)), 0.0, math.cos(math.radians(arc))])


def vec(v) -> str:
    return "[" + ", ".join(repr(float(c)) for c in v) + "]"


def drawing(arcs=ARCS, off=OFF, tip_axis="bodies") -> str:
    """The five-bar as part drawings: each link in its own frame (origin at the
    centre, anchors on the sphere, axes z and at ``arc`` from it); the ground joints by
    world anchor and axis; B and D's axes as drawn in [[joints]] (world), the tip's in
    the two links' ``axes`` (each link's own)."""
    n = rest_axes()
    links = [("A", "B"), ("B", "C"), ("C", "D"), ("D", "E")]
    turns = [np.eye(3), turn(n["B"], off[0]), turn(n["D"], off[1]), np.eye(3)]
    text = '[mechanism]\nname = "spherical five-bar"\nground = "ground"\n'
    text += 'units = "mm"\nassemble = true\n\n[[bodies]]\nname = "ground"\n'
    for k, ((first, second), arc) in enumerate(zip(links, arcs)):
        rot = turns[k] @ frame_to(n[first], n[second], ARCS[k])
        x, y, z, w = Rotation.from_matrix(rot).as_quat()
        local = {first: np.array([0.0, 0.0, 1.0]), second: local_axis(arc)}
        anchors = ", ".join(f"{j} = {vec(RADIUS * v)}" for j, v in local.items())
        text += f'\n[[bodies]]\nname = "link{k + 1}"\nframe = {vec(CENTRE)}\n'
        text += f"orientation = {vec([w, x, y, z])}\nanchors = {{ {anchors} }}\n"
        if "C" in local and tip_axis == "bodies":
            text += f"axes = {{ C = {vec(local['C'])} }}\n"
    pairs = {"A": ("ground", "link1"), "B": ("link1", "link2")}
    pairs |= {"C": ("link2", "link3"), "D": ("link3", "link4")}
    pairs |= {"E": ("ground", "link4")}
    for name, (b1, b2) in pairs.items():
        text += f'\n[[joints]]\nname = "{name}"\ntype = "revolute"\n'
        text += f'bodies = ["{b1}", "{b2}"]\n'
        if name in "AE":
            text += f"anchor = {vec(CENTRE + RADIUS * n[name])}\n"
        if name in "ABDE" or tip_axis == "joints":
            text += f"axis = {vec(n[name])}\n"
    c = CENTRE + RADIUS * n["C"]
    text += '\n[[motors]]\nname = "m1"\njoint = "A"\n'
    text += '\n[[motors]]\nname = "m2"\njoint = "E"\n'
    text += '\n[[points]]\nname = "tip"\nbody = "link2"\njoint = "C"\n'
    for k, coordinate in enumerate("xy"):
        text += f'\n[[outputs]]\nname = "{coordinate}"\npoint = "tip"\n'
        text += f'coordinate = "{coordinate}"\n'
        text += f"min = {float(c[k]) - 5.0!r}\nmax = {float(c[k]) + 5.0!r}\n"
    return text


@pytest.fixture(scope="module")
def assembled():
    return assemble(parse_toml(drawing(), "sph.toml"), "sph.toml")


def world_axes(data: dict) -> dict[str, np.ndarray]:
    return {j["name"]: np.array(j["axis"]) for j in data["joints"]}


def test_tip_drawn_off_assembles_where_the_closed_form_puts_it(assembled):
    """With both motors held at their drawn values, the cranks stay and the tip closes
    at the closed-form tip; every written axis passes through the centre."""
    exact = rest_axes()
    anchors = {j["name"]: np.array(j["anchor"]) for j in assembled.data["joints"]}
    axes = world_axes(assembled.data)
    for name, n in exact.items():
        np.testing.assert_allclose(anchors[name], CENTRE + RADIUS * n, atol=1e-9)
        np.testing.assert_allclose(axes[name], n, atol=1e-9)
        along = anchors[name] - CENTRE
        assert np.linalg.norm(np.cross(along, axes[name])) < 1e-9
    assert assembled.report.residual < 1e-9
    moved = {m.joint: m.distance for m in assembled.report.moves}
    assert moved["A"] == moved["E"] == 0.0 and moved["C"] > 1.0


def closed_form(m1: float, m2: float) -> dict[str, np.ndarray]:
    """The axes of A..E with the motors turned by ``m1``, ``m2`` (rad) from rest."""
    a, e = ground_axes()
    rest = rest_axes()
    b = turn(a, math.degrees(m1)) @ rest["B"]
    d = turn(e, math.degrees(m2)) @ rest["D"]
    return {"A": a, "B": b, "C": tip(b, d), "D": d, "E": e}


def test_motors_turned_from_the_drawing_carry_the_moving_axes():
    """``--motors`` turns the cranks from an exact drawing (every axis in [[joints]]):
    the axes of B, C and D turn with the links that carry them, to the closed form.
    Held as written, they kept the cranks from turning at all."""
    data = parse_toml(drawing(off=(0.0, 0.0), tip_axis="joints"), "sph.toml")
    result = assemble(data, "sph.toml", motors=np.array([0.2, -0.1]))
    anchors = {j["name"]: np.array(j["anchor"]) for j in result.data["joints"]}
    axes = world_axes(result.data)
    for name, n in closed_form(0.2, -0.1).items():
        np.testing.assert_allclose(anchors[name], CENTRE + RADIUS * n, atol=1e-9)
        np.testing.assert_allclose(axes[name], n, atol=1e-9)


def test_written_file_passes_check_and_its_fk_is_the_closed_form(tmp_path, capsys):
    source = tmp_path / "spherical_drawn.toml"
    source.write_text(drawing())
    out = tmp_path / "spherical.toml"
    assert main(["assemble", str(source), "--out", str(out)]) == 0
    assert main(["check", str(out)]) == 0
    capsys.readouterr()
    mech = linkopt.load(out)
    names = list(mech.joint_names)
    motors = np.array([[0.0, 0.0], [0.15, -0.1], [-0.2, 0.12], [0.1, 0.2]])
    solution = linkopt.solve_fk(mech, motors)
    assert np.all(np.asarray(solution.converged))
    joints = np.asarray(linkopt.joint_positions(mech, solution.state))
    for k, (m1, m2) in enumerate(motors):
        for name, n in closed_form(m1, m2).items():
            got = joints[k, names.index(name)]
            np.testing.assert_allclose(got, CENTRE + RADIUS * n, rtol=0, atol=1e-9)


def test_spherical_loop_that_cannot_close_names_its_loop_and_gap():
    """Four links of 12° cannot reach across a ground arc of 60°: the message names
    the loop (its joints and bodies), what cannot hold, the gap in mm (at least what
    the four link chords, pulled straight, lack of the ground chord) and the axes held
    as written."""
    arcs = (12.0, 12.0, 12.0, 12.0)
    data = parse_toml(drawing(arcs=arcs, off=(0.0, 0.0)), "short.toml")
    with pytest.raises(linkopt.MechanismFileError) as err:
        assemble(data, "short.toml")
    message = str(err.value)
    assert (
        "the loop through joints A, B, C, D, E (bodies ground, link1, link2, link3, "
        "link4) does not close: the anchors of link1, link2, link3, link4 in their "
        "frames; the axes of A, B, C, D, E cannot all hold" in message
    )
    gap = float(re.search(r"misses by ([0-9.e+-]+) mm", message).group(1))
    chord = 2 * RADIUS * math.sin(math.radians(GROUND / 2))
    link = 2 * RADIUS * math.sin(math.radians(arcs[0] / 2))
    assert gap >= chord - 4 * link > 8.0
    assert message.endswith("the axes of A, E are held as written (on the ground)")


def world_drawing() -> str:
    """The same five-bar with every body given by world anchors: axes in [[joints]],
    the tip drawn 4° off about B (anchor and axis), the links' chords B–C and C–D
    declared."""
    n = rest_axes()
    off = turn(n["B"], 4.0) @ n["C"]
    axes = dict(n, C=off)
    text = '[mechanism]\nname = "w"\nground = "ground"\nunits = "mm"\n'
    text += "assemble = true\n"
    for body in ("ground", "link1", "link2", "link3", "link4"):
        text += f'[[bodies]]\nname = "{body}"\n'
    pairs = {"A": ("ground", "link1"), "B": ("link1", "link2")}
    pairs |= {"C": ("link2", "link3"), "D": ("link3", "link4")}
    pairs |= {"E": ("ground", "link4")}
    for name, (b1, b2) in pairs.items():
        text += f'[[joints]]\nname = "{name}"\ntype = "revolute"\n'
        text += f'bodies = ["{b1}", "{b2}"]\n'
        text += f"anchor = {vec(CENTRE + RADIUS * axes[name])}\n"
        text += f"axis = {vec(axes[name])}\n"
    chord = 2 * RADIUS * math.sin(math.radians(ARCS[1] / 2))
    for pair in (("B", "C"), ("C", "D")):
        text += f'[[lengths]]\njoints = ["{pair[0]}", "{pair[1]}"]\n'
        text += f"length = {chord!r}\n"
    text += '[[motors]]\nname = "m1"\njoint = "A"\n'
    text += '[[motors]]\nname = "m2"\njoint = "E"\n'
    return text


def test_spatial_loop_of_world_bodies_names_the_axes_it_holds():
    """Given by world anchors, the links hold their axes as written: the loop closes
    only by turning them off those axes, which would write a file whose axes miss the
    centre (it was refused later, as "mobility 0 at the rest pose but 2 motor(s)").
    The message names the loop, the turned bodies and the held axes."""
    data = parse_toml(world_drawing(), "world.toml")
    with pytest.raises(linkopt.MechanismFileError) as err:
        assemble(data, "world.toml")
    message = str(err.value)
    assert message.startswith("world.toml: bodies[1]: the loop through joints A, B, C")
    assert "(bodies ground, link1, link2, link3, link4) closes only by turning" in (
        message
    )
    assert "held as written on bodies given by world anchors" in message
    assert message.endswith("for the axes to turn with them")


HOOKE = """
[mechanism]
name = "hooke"
ground = "ground"
assemble = true
[[bodies]]
name = "ground"
[[bodies]]
name = "yoke1"
frame = [0.0, 0.0, 0.0]
anchors = {{ A = [-50.0, 0.0, 0.0], U = [0.0, 0.0, 0.0] }}
axes = {{ U = [0.0, 0.0, 1.0] }}
[[bodies]]
name = "yoke2"
frame = [0.0, 0.0, 0.0]
orientation = {orientation}
anchors = {{ U = [0.0, 0.0, 0.0], B = {b} }}
axes = {{ U = {cross} }}
[[joints]]
name = "A"
type = "revolute"
bodies = ["ground", "yoke1"]
anchor = [-50.0, 0.0, 0.0]
axis = [1.0, 0.0, 0.0]
[[joints]]
name = "U"
type = "universal"
bodies = ["yoke1", "yoke2"]
[[joints]]
name = "B"
type = "revolute"
bodies = ["yoke2", "ground"]
anchor = {b}
axis = {shaft}
[[motors]]
name = "m"
joint = "A"
[[outputs]]
name = "out"
joint = "B"
min = -0.1
max = 0.1
"""


def test_hooke_joint_cross_assembles_perpendicular():
    """A Hooke joint between shafts 30° apart, the output yoke drawn turned 5° about
    its shaft so that the cross's arms are not perpendicular: the yokes turn about
    their shafts until ``axis`` ⟂ ``axis2`` (a universal joint's one row), each arm
    stays perpendicular to its shaft, and the written file loads."""
    shaft = np.array([math.cos(math.radians(30)), math.sin(math.radians(30)), 0.0])
    cross = np.cross([0.0, 0.0, 1.0], shaft)
    x, y, z, w = Rotation.from_rotvec(math.radians(5) * shaft).as_quat()
    text = HOOKE.format(
        orientation=vec([w, x, y, z]),
        b=vec(50 * shaft),
        cross=vec(cross),
        shaft=vec(shaft),
    )
    result = assemble(parse_toml(text, "hooke.toml"), "hooke.toml")
    joint = result.data["joints"][1]
    first, second = np.array(joint["axis"]), np.array(joint["axis2"])
    assert abs(first @ second) < 1e-12
    assert abs(first[0]) < 1e-12 and abs(second @ shaft) < 1e-12
    np.testing.assert_allclose(np.array(joint["anchor"]), 0.0, atol=1e-12)
    assert linkopt.loads(dumps(result.data), "hooke_assembled.toml").num_motors == 1
