"""Named points move with their bodies (issue 27, part 1): when a design moves a
body's anchors, a point keeps its place among them; a point on a body given in its own
frame is written in that frame."""

import math

import delta_closed_form as dc
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS
from hypothesis import example, given
from hypothesis import strategies as st

import linkopt
from linkopt._engine.attachment import LINE, PLANE, POINT, SPACE, attach
from linkopt._engine.following import follow
from linkopt._engine.geometry import geometry
from linkopt._files.assembly import assemble
from linkopt._files.fields import parse_toml
from linkopt._files.writer import write_design

DESIGNS = np.array([[80.0, 180.0], [80.0, 210.0], [95.0, 160.0], [70.0, 200.0]])
MOTORS = np.array([[0.0, 0.0, 0.0], [0.3, -0.2, 0.5], [-0.4, 0.2, 0.1]])


@pytest.fixture(scope="module")
def delta():
    return linkopt.load(MECHANISMS / "delta.toml")


def wrists(mech) -> np.ndarray:
    return np.array([k for k, n in enumerate(mech.joint_names) if "wrist" in n])


def test_delta_tcp_stays_at_the_centre_of_the_wrists_for_every_design(delta):
    """The file puts ``tcp`` at the centroid of the six wrist anchors; a longer or
    shorter rod or arm keeps it there (it ended 23.7 mm off for a rod of 210)."""
    assert delta.design.names == ("arm", "rod")
    for design in DESIGNS:  # at rest and two poses: the block programs of a batch
        solution = linkopt.solve_fk(delta, MOTORS, design=design)
        assert np.all(np.asarray(solution.converged))
        states = solution.state
        joints = np.asarray(linkopt.joint_positions(delta, states, design=design))
        tcp = np.asarray(linkopt.point_positions(delta, states, design=design))[:, 0]
        np.testing.assert_allclose(
            tcp, joints[:, wrists(delta)].mean(1), rtol=0, atol=1e-9
        )


def test_delta_tcp_is_the_closed_form_platform_centre_at_every_design(delta):
    """FK's ``tcp`` against the three-sphere intersection of the delta whose sizes the
    design gives (read off its rest anchors)."""
    names = list(delta.joint_names)
    for design in DESIGNS[1:]:
        anchors = np.asarray(geometry(delta, design).anchors) * delta.length_scale
        elbow, wrist = anchors[names.index("elbow1a")], anchors[names.index("wrist1a")]
        sizes = dict(dc.SIZES, arm=elbow[0] - dc.SIZES["base"], platform=wrist[0])
        sizes["rod"] = float(np.linalg.norm(elbow - wrist))
        solution = linkopt.solve_fk(delta, MOTORS, design=design)
        assert np.all(np.asarray(solution.converged))
        tcp = np.asarray(linkopt.point_positions(delta, solution.state, design=design))[
            :, 0
        ]
        np.testing.assert_allclose(
            tcp, dc.platform_centre(MOTORS, sizes), rtol=0, atol=1e-8
        )


def test_written_design_puts_the_point_where_the_design_did(delta, tmp_path):
    design = DESIGNS[1]
    path = write_design(delta, design, 1.0, tmp_path / "longer_rods.toml")
    written = linkopt.load(path)
    np.testing.assert_allclose(
        written.point_positions,
        np.asarray(geometry(delta, design).points) * delta.length_scale,
        rtol=0,
        atol=1e-9,
    )
    states = linkopt.solve_fk(written, MOTORS).state
    joints = np.asarray(linkopt.joint_positions(written, states))
    tcp = np.asarray(linkopt.point_positions(written, states))[:, 0]
    np.testing.assert_allclose(tcp, joints[:, wrists(written)].mean(1), atol=1e-9)


TURNED_PLATFORM = """
[mechanism]
name = "turned"
ground = "ground"
assemble = true
[[bodies]]
name = "ground"
[[bodies]]
name = "crank"
[[bodies]]
name = "platform"
frame = [{x}, {y}, 0.0]
orientation = [{qw}, 0.0, 0.0, {qz}]
anchors = {{ b = [-20.0, 0.0, 0.0], c = [20.0, 0.0, 0.0] }}
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
bodies = ["crank", "platform"]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "c"
type = "revolute"
bodies = ["platform", "rocker"]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "d"
type = "revolute"
bodies = ["rocker", "ground"]
anchor = [{d[0]}, {d[1]}, 0.0]
axis = [0.0, 0.0, 1.0]
[[lengths]]
joints = ["a", "b"]
length = 15.0
[[lengths]]
joints = ["c", "d"]
length = 35.0
[[motors]]
name = "crank"
joint = "a"
[[points]]
name = "p"
body = "platform"
position = [5.0, 0.0, 0.0]
[[outputs]]
name = "rocker"
joint = "d"
min = -0.1
max = 0.1
"""


@pytest.mark.parametrize("turn", [math.pi / 2, 0.3])
def test_point_on_a_body_in_a_turned_frame_lands_where_the_frame_says(turn):
    """A point written ``[5, 0, 0]`` on a platform whose frame is turned lies 5 along
    the platform's local x from its frame origin, midway between its joints b and c:
    read as a world position it ended at (4.983, 0.415) for a quarter turn."""
    b, c = (
        np.array([8.0, 13.0]),
        np.array([8.0, 13.0]) + 40.0 * np.array([math.cos(turn), math.sin(turn)]),
    )
    d = c + [35.0, 0.0]  # the rocker's ground joint, 35 from c
    frame = (b + c) / 2
    text = TURNED_PLATFORM.format(
        x=frame[0], y=frame[1], qw=math.cos(turn / 2), qz=math.sin(turn / 2), d=d
    )
    data = parse_toml(text, "turned.toml")
    result = assemble(data, "turned.toml")
    got = {j["name"]: np.array(j["anchor"]) for j in result.data["joints"]}
    axis = (got["c"] - got["b"]) / np.linalg.norm(got["c"] - got["b"])
    expected = (got["b"] + got["c"]) / 2 + 5.0 * axis
    point = np.array(result.data["points"][0]["position"])
    np.testing.assert_allclose(point, expected, rtol=0, atol=1e-9)


# --- the attachment rule on its own ---------------------------------------------------


def rotation(angles) -> np.ndarray:
    a, b, c = angles
    rx = np.array(
        [[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]]
    )
    ry = np.array(
        [[math.cos(b), 0, math.sin(b)], [0, 1, 0], [-math.sin(b), 0, math.cos(b)]]
    )
    rz = np.array(
        [[math.cos(c), -math.sin(c), 0], [math.sin(c), math.cos(c), 0], [0, 0, 1]]
    )
    return rz @ ry @ rx


BODIES = {
    "one anchor": (np.array([[1.0, 2.0, 3.0]]), POINT),
    "line": (np.array([[0.0, 0.0, 0.0], [4.0, 1.0, 0.5], [8.0, 2.0, 1.0]]), LINE),
    "plane": (np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [1.0, 3.0, 0.0]]), PLANE),
    "space": (
        np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [1.0, 3.0, 0.0], [1, 1, 2.0]]),
        SPACE,
    ),
}


def attached(anchors, point):
    on_body = [np.arange(len(anchors))]
    return attach(anchors, on_body, point[None], np.array([-1]), 10.0)


@pytest.mark.parametrize("body", BODIES)
@given(
    point=st.lists(st.floats(-5, 5), min_size=3, max_size=3),
    angles=st.lists(st.floats(-3, 3), min_size=3, max_size=3),
    shift=st.lists(st.floats(-5, 5), min_size=3, max_size=3),
)
@example(point=[0.0, 0.0, 1e-8], angles=[1.0, 0.0, 0.0], shift=[0.0, 0.0, 0.0])
def test_a_rigid_move_of_the_anchors_moves_the_point_rigidly(
    body, point, angles, shift
):
    anchors, hull = BODIES[body]
    point = np.asarray(point)
    att = attached(anchors, point)
    gap = np.min(np.linalg.norm(anchors - point, axis=1))
    on_anchor = gap <= 1e-8
    assert att.hulls[0] == (SPACE if on_anchor else hull)  # on one: it follows it
    turn = rotation(angles)
    if hull == POINT:  # one anchor position fixes no rotation: translate only
        turn = np.eye(3)
    elif hull == LINE:  # a line fixes no rotation about itself: turn about a normal
        u = (anchors[1] - anchors[0]) / np.linalg.norm(anchors[1] - anchors[0])
        n = np.cross(u, [0.0, 0.0, 1.0])
        n /= np.linalg.norm(n)
        k = np.array([[0, -n[2], n[1]], [n[2], 0, -n[0]], [-n[1], n[0], 0]])
        turn = np.eye(3) + math.sin(angles[0]) * k + (1 - math.cos(angles[0])) * k @ k
    moved = anchors @ turn.T + shift
    got = follow(att, point[None], anchors, jnp.asarray(moved))[0]
    # a point snapped onto an anchor follows that anchor: off by at most twice
    # its gap
    slack = 2.0 * gap if on_anchor else 0.0
    np.testing.assert_allclose(got, turn @ point + shift, rtol=0, atol=1e-9 + slack)


@pytest.mark.parametrize("body", ["line", "plane", "space"])
def test_a_point_inside_the_anchors_keeps_its_affine_place_when_they_stretch(body):
    anchors, _ = BODIES[body]
    point = anchors.mean(0) + 0.25 * (anchors[1] - anchors[0])
    att = attached(anchors, point)
    stretch = np.diag([1.5, 0.7, 1.2])
    got = follow(att, point[None], anchors, jnp.asarray(anchors @ stretch))[0]
    np.testing.assert_allclose(got, stretch @ point, rtol=0, atol=1e-12)


def test_a_point_on_an_anchor_follows_that_anchor():
    anchors, _ = BODIES["space"]
    att = attached(anchors, anchors[2])
    assert np.array_equal(att.weights[0], np.eye(4)[2])
    moved = anchors.copy()
    moved[2] += [1.0, -2.0, 0.5]
    got = follow(att, anchors[2][None], anchors, jnp.asarray(moved))[0]
    np.testing.assert_allclose(got, moved[2], rtol=0, atol=1e-15)


@pytest.mark.parametrize("body", ["line", "plane"])
def test_the_followed_point_is_smooth_in_the_anchors(body):
    """Its Jacobian in the anchors against central differences (the design gradient
    goes through it)."""
    anchors, _ = BODIES[body]
    point = anchors.mean(0) + np.array([0.3, -1.2, 2.0])
    att = attached(anchors, point)
    moved = anchors + 0.1 * np.sin(np.arange(anchors.size)).reshape(anchors.shape)

    def where(a):
        return follow(att, point[None], anchors, a.reshape(anchors.shape))[0]

    x = jnp.asarray(moved.ravel())
    jac = np.asarray(jax.jacfwd(where)(x))
    h = 1e-6
    for i in range(x.size):
        e = np.zeros(x.size)
        e[i] = h
        fd = (np.asarray(where(x + e)) - np.asarray(where(x - e))) / (2 * h)
        np.testing.assert_allclose(jac[:, i], fd, rtol=0, atol=1e-7)


def test_fk_on_the_command_line_takes_a_design(capsys):
    """``linkopt fk --design``: the delta with rods of 210 puts ``tcp`` at the centre
    of its wrists, 210/180 of the rest drop sqrt(180² - 110²) below the base (a longer
    rod moves the wrists along the rods' rest direction; the arms stay level)."""
    import json

    from linkopt._cli.main import main

    path = str(MECHANISMS / "delta.toml")
    assert main(["fk", path, "--motors", "0,0,0", "--design", "80,210", "--json"]) == 0
    fk = json.loads(capsys.readouterr().out)
    wrists = np.array([v for k, v in fk["joints"].items() if "wrist" in k])
    np.testing.assert_allclose(fk["points"]["tcp"], wrists.mean(0), atol=1e-9)
    rise = 210.0 / 180.0 * np.sqrt(180.0**2 - 110.0**2)
    assert fk["points"]["tcp"][2] == pytest.approx(-rise, abs=1e-9)
    assert main(["fk", path, "--motors", "0,0,0", "--design", "80"]) == 2
    assert "design" in capsys.readouterr().err
