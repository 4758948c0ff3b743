"""Theo Jansen's leg (mechanisms/jansen_1dof.toml) against an independent
circle-intersection model."""

from pathlib import Path

import numpy as np
import pytest

import linkopt

FILE = Path(__file__).resolve().parent.parent / "mechanisms" / "jansen_1dof.toml"

# Jansen's published link lengths.
JANSEN = dict(
    a=38.0,
    b=41.5,
    c=39.3,
    d=40.1,
    e=55.8,
    f=39.4,
    g=36.7,
    h=65.7,
    i=49.0,
    j=50.0,
    k=61.9,
    l=7.8,
    m=15.0,
)
O = np.array([0.0, 0.0])  # noqa: E741  (Jansen's name for the crank centre)
A = np.array([-JANSEN["a"], -JANSEN["l"]])
STEPS = 72


@pytest.fixture(scope="module")
def jansen() -> linkopt.Mechanism:
    return linkopt.load(FILE)


def _circles(p1, r1, p2, r2):
    """Both intersections of the circles (p1, r1) and (p2, r2): left and right of p1 ->
    p2."""
    d = p2 - p1
    dist = np.hypot(*d)
    along = (dist**2 + r1**2 - r2**2) / (2.0 * dist)
    height = np.sqrt(r1**2 - along**2)
    unit = d / dist
    normal = np.array([-unit[1], unit[0]])
    base = p1 + along * unit
    return base + height * normal, base - height * normal


def _leg(theta, previous=None):
    """Joint positions of the leg for crank angle ``theta`` (from +x).

    Without ``previous``, Jansen's standard branch: B upper, D lower, E left, F left
    (outer), G lowest. With ``previous`` (the pose one small step back), each point
    takes the intersection nearer its previous position, so the branch is followed by
    continuity.
    """
    L = JANSEN
    pose = {"O": O, "A": A, "C": L["m"] * np.array([np.cos(theta), np.sin(theta)])}
    rules = {
        "B": ("A", L["b"], "C", L["j"], lambda u, v: u if u[1] > v[1] else v),
        "D": ("A", L["c"], "C", L["k"], lambda u, v: u if u[1] < v[1] else v),
        "E": ("A", L["d"], "B", L["e"], lambda u, v: u if u[0] < v[0] else v),
        "F": ("E", L["f"], "D", L["g"], lambda u, v: u if u[0] < v[0] else v),
        "G": ("F", L["h"], "D", L["i"], lambda u, v: u if u[1] < v[1] else v),
    }
    for name, (p1, r1, p2, r2, standard) in rules.items():
        u, v = _circles(pose[p1], r1, pose[p2], r2)
        if previous is None:
            pose[name] = standard(u, v)
        else:
            near = np.linalg.norm(u - previous[name]) < np.linalg.norm(
                v - previous[name]
            )
            pose[name] = u if near else v
    return pose


def _links(pose):
    """Jansen's letter -> distance between the two points it joins."""
    pairs = dict(
        a=None,
        b="AB",
        c="AD",
        d="AE",
        e="BE",
        f="EF",
        g="DF",
        h="FG",
        i="DG",
        j="BC",
        k="CD",
        l=None,
        m="OC",
    )
    return {
        key: float(np.linalg.norm(pose[p[0]] - pose[p[1]]))
        for key, p in pairs.items()
        if p
    }


def _file_pose(mech, joints, foot):
    """Points O, A, B, C, D, E, F, G of the leg from joint and foot positions (x, y)."""
    index = {name: k for k, name in enumerate(mech.joint_names)}
    names = dict(O="O", A="A_triangle", B="B", C="C_j", D="D_kc", E="E", F="F")
    pose = {
        key: np.asarray(joints)[..., index[name], :2] for key, name in names.items()
    }
    pose["G"] = np.asarray(foot)[..., :2]
    return pose


def test_link_lengths_are_jansens(jansen):
    index = {name: k for k, name in enumerate(jansen.joint_names)}
    pose = _file_pose(
        jansen, jansen.anchors, jansen.point_positions[jansen.point_names.index("foot")]
    )
    np.testing.assert_array_equal(pose["O"], [0.0, 0.0])
    np.testing.assert_array_equal(pose["A"], A)
    for a, b in [("C_j", "C_k"), ("A_triangle", "A_c"), ("D_kc", "D_foot")]:
        np.testing.assert_array_equal(
            jansen.anchors[index[a]], jansen.anchors[index[b]]
        )
    assert np.all(jansen.anchors[:, 2] == 0.0) and jansen.point_positions[0, 2] == 0.0
    np.testing.assert_array_equal(
        jansen.axes, np.tile([0.0, 0.0, 1.0], (len(jansen.joint_names), 1))
    )
    for key, length in _links(pose).items():
        assert abs(length - JANSEN[key]) <= 1e-9, (key, length, JANSEN[key])
    # The file's rest pose is the standard branch at crank angle 0.
    standard = _leg(0.0)
    for key in "BCDEFG":
        np.testing.assert_allclose(pose[key], standard[key], atol=1e-12)


def test_topology(jansen):
    assert jansen.num_bodies == 8 and jansen.state_size == 56
    assert linkopt.mobility(jansen) == 1
    assert set(jansen.joint_types) == {"revolute"} and len(jansen.joint_names) == 10
    assert (
        jansen.motor_names == ("crank",)
        and jansen.joint_names[jansen.motor_joints[0]] == "O"
    )


@pytest.fixture(scope="module")
def full_turn(jansen):
    motors = np.linspace(0.0, 2.0 * np.pi, STEPS + 1)[1:, None]
    path = linkopt.solve_fk_path(jansen, motors, start=linkopt.rest_state(jansen))
    return motors, path


def test_foot_path_matches_circle_intersection(jansen, full_turn):
    motors, path = full_turn
    assert np.all(np.asarray(path.converged))
    assert float(np.max(path.residual)) <= 1e-10

    expected, previous = [], _leg(0.0)
    for theta in motors[:, 0]:
        previous = _leg(theta, previous)
        expected.append(previous)
    foot = np.asarray(linkopt.point_positions(jansen, path.state))[
        :, jansen.point_names.index("foot")
    ]
    np.testing.assert_allclose(
        foot[:, :2], np.array([p["G"] for p in expected]), atol=1e-8
    )
    np.testing.assert_allclose(foot[:, 2], 0.0, atol=1e-10)

    # Every joint on the independent model, and each coincident joint pair closed.
    joints = np.asarray(linkopt.joint_positions(jansen, path.state))
    pose = _file_pose(jansen, joints, foot)
    for key in "BCDEF":
        np.testing.assert_allclose(
            pose[key], np.array([p[key] for p in expected]), atol=1e-8
        )
    index = {name: k for k, name in enumerate(jansen.joint_names)}
    for a, b in [("C_j", "C_k"), ("A_triangle", "A_c"), ("D_kc", "D_foot")]:
        np.testing.assert_allclose(joints[:, index[a]], joints[:, index[b]], atol=1e-9)

    # The motor reads back the commanded crank angle (wrapped to (-pi, pi]).
    read = np.asarray(linkopt.motor_values(jansen, path.state))[:, 0]
    np.testing.assert_allclose(
        np.angle(np.exp(1j * (read - motors[:, 0]))), 0.0, atol=1e-10
    )

    # The classic Jansen foot path: a flat stance at the bottom, x within about 68
    # units.
    assert -71.6 < foot[:, 0].min() < -71.0 and -4.0 < foot[:, 0].max() < -3.5
    assert -91.9 < foot[:, 1].min() < -91.7 and -70.0 < foot[:, 1].max() < -69.0


def test_full_turn_returns_to_rest(jansen, full_turn):
    _, path = full_turn
    rest = np.asarray(linkopt.rest_state(jansen)).reshape(-1, 7)
    final = np.asarray(path.state[-1]).reshape(-1, 7)
    np.testing.assert_allclose(final[:, :3], rest[:, :3], atol=1e-10)
    # A full turn of the crank takes its quaternion q to -q: the same rotation.
    sign = np.sign(np.sum(final[:, 3:] * rest[:, 3:], axis=1, keepdims=True))
    np.testing.assert_allclose(sign * final[:, 3:], rest[:, 3:], atol=1e-10)
    np.testing.assert_allclose(
        linkopt.point_positions(jansen, path.state[-1]),
        linkopt.point_positions(jansen, rest.ravel()),
        atol=1e-9,
    )
    np.testing.assert_allclose(
        linkopt.motor_values(jansen, path.state[-1]), [0.0], atol=1e-10
    )


def test_single_solves_over_a_full_turn_stay_on_the_rest_branch(jansen):
    """Regression: ``fk --motors 3.14159265359`` from the rest pose landed on another
    assembly of the leg (foot near (-60, -48)). Each crank angle, solved on its own
    without a start state, must give the standard branch reached by continuity."""
    thetas = np.linspace(0.0, 2.0 * np.pi, 24, endpoint=False)
    expected, previous = {}, _leg(0.0)
    for theta in np.linspace(0.0, 2.0 * np.pi, 24 * 30, endpoint=False):
        previous = _leg(theta, previous)
        expected[round(float(theta), 9)] = previous
    batch = linkopt.solve_fk(jansen, thetas[:, None])
    assert np.all(np.asarray(batch.converged))
    np.testing.assert_array_equal(np.asarray(batch.progress), 1.0)
    joints = np.asarray(linkopt.joint_positions(jansen, batch.state))
    foot = np.asarray(linkopt.point_positions(jansen, batch.state))[:, 0]
    pose = _file_pose(jansen, joints, foot)
    for k, theta in enumerate(thetas):
        reference = expected[round(float(theta), 9)]
        for key in "BCDEFG":
            np.testing.assert_allclose(pose[key][k], reference[key], atol=1e-8)
    for k in (0, 12, 23):  # one call each: the same answer as the batch
        one = linkopt.solve_fk(jansen, thetas[k : k + 1])
        np.testing.assert_allclose(one.state, batch.state[k], atol=1e-9)
    half = linkopt.point_positions(jansen, linkopt.solve_fk(jansen, [np.pi]).state)
    np.testing.assert_allclose(np.asarray(half)[0, :2], [-33.7297, -73.5171], atol=1e-3)
