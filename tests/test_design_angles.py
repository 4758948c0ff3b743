"""Link angles as design parameters (issue 45, part 2): ``kind = "twist"`` sets the
angle between two joint axes of one link, turning the ``to`` joint about the common
normal, so a spherical mechanism stays spherical (every axis through the centre, every
anchor on its sphere); ``kind = "offset"`` sets the distance between parallel axes.
Checked against closed forms (the rest axes, the spherical five-bar's FK), finite
differences (the optimiser's partial gradient) and
malformed files."""

import functools
import math

import jax
import numpy as np
import pytest
from conftest import MECHANISMS
from test_design_parameters import parsed

import linkopt
from linkopt._design.evaluation import alpha_minus, evaluate
from linkopt._design.partial import frozen_objective, partial_gradient
from linkopt._engine.geometry import geometry
from linkopt._engine.lifting import padded
from linkopt._engine.structure import structure

TEXT = (MECHANISMS / "spherical_five_bar.toml").read_text()
RADIUS = 50.0
NAMES = "ABCDE"
DESIGN = np.array([0.75, 1.0, 1.4])  # proximal left, proximal right, distal left


@pytest.fixture(scope="module")
def sph():
    return linkopt.load(MECHANISMS / "spherical_five_bar.toml")


def unit_axes(mech, design) -> dict[str, np.ndarray]:
    axes = np.asarray(geometry(mech, design).axes)
    return dict(zip(mech.joint_names, axes))


def angle(u, v) -> float:
    return math.atan2(np.linalg.norm(np.cross(u, v)), u @ v)


def arc_from(a: np.ndarray, towards: np.ndarray, arc: float) -> np.ndarray:
    """The unit vector at ``arc`` from ``a`` in the plane of ``a`` and ``towards``."""
    w = towards - (towards @ a) * a
    return math.cos(arc) * a + math.sin(arc) * w / np.linalg.norm(w)


def rest_closed_form(mech, design) -> dict[str, np.ndarray]:
    """The axes at rest of a design: B at the proximal arc from A in the plane of A and
    the file's B, D likewise from E, C at the distal arc from B in the plane of B and
    the file's C turned with B (the turn of link1 carries link2)."""
    n = unit_axes(mech, None)
    b = arc_from(n["A"], n["B"], design[0])
    d = arc_from(n["E"], n["D"], design[1])
    turn = _rotation_between(n["B"], b, np.cross(n["A"], n["B"]))
    c = arc_from(b, turn @ n["C"], design[2])
    return {"A": n["A"], "B": b, "C": c, "D": d, "E": n["E"]}


def _rotation_between(u, v, axis) -> np.ndarray:
    """The rotation about ``axis`` (perpendicular to both) taking ``u`` to ``v``."""
    k = axis / np.linalg.norm(axis)
    theta = math.atan2(np.cross(u, v) @ k, u @ v)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(theta) * cross + (1 - math.cos(theta)) * cross @ cross


def test_twists_are_the_link_angles_and_the_mechanism_stays_spherical(sph):
    np.testing.assert_allclose(sph.design.p0, np.radians([50.0, 50.0, 70.0]))
    axes = unit_axes(sph, DESIGN)
    anchors = dict(zip(sph.joint_names, np.asarray(geometry(sph, DESIGN).anchors)))
    want = rest_closed_form(sph, DESIGN)
    for name in NAMES:
        np.testing.assert_allclose(axes[name], want[name], atol=1e-13)
        anchor = anchors[name] * sph.length_scale
        assert abs(np.linalg.norm(anchor) - RADIUS) < 1e-12
        assert np.linalg.norm(np.cross(anchor, axes[name])) < 1e-12
    got = [angle(axes["A"], axes["B"]), angle(axes["E"], axes["D"])]
    got.append(angle(axes["B"], axes["C"]))
    np.testing.assert_allclose(got, DESIGN, atol=1e-14)


def tip(b, d, arcs, side) -> np.ndarray:
    """Closed form of the spherical five-bar: the unit axis at ``arcs`` from ``b`` and
    ``d``, on ``side`` of ``b × d``."""
    g = b @ d
    u, v = np.linalg.solve([[1.0, g], [g, 1.0]], np.cos(arcs))
    m = u * b + v * d
    normal = np.cross(b, d)
    return m + side * math.sqrt(1.0 - m @ m) / np.linalg.norm(normal) * normal


def test_fk_of_a_twisted_design_is_the_spherical_closed_form(sph):
    rest = rest_closed_form(sph, DESIGN)
    arcs = np.array([DESIGN[2], angle(rest["C"], rest["D"])])
    side = np.sign(np.cross(rest["B"], rest["D"]) @ rest["C"])
    motors = np.array([[0.0, 0.0], [0.15, -0.1], [-0.2, 0.12], [0.1, 0.2]])
    solution = linkopt.solve_fk(sph, motors, design=DESIGN)
    assert np.all(np.asarray(solution.converged))
    joints = np.asarray(linkopt.joint_positions(sph, solution.state, design=DESIGN))
    names = list(sph.joint_names)
    for k, (m1, m2) in enumerate(motors):
        b = _axis_angle(rest["A"], m1) @ rest["B"]
        d = _axis_angle(rest["E"], m2) @ rest["D"]
        want = {"B": b, "C": tip(b, d, arcs, side), "D": d}
        for name, n in want.items():
            got = joints[k, names.index(name)]
            np.testing.assert_allclose(got, RADIUS * n, rtol=0, atol=1e-9)


def _axis_angle(axis, theta) -> np.ndarray:
    k = axis / np.linalg.norm(axis)
    cross = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(theta) * cross + (1 - math.cos(theta)) * cross @ cross


def test_a_written_twisted_design_shares_the_program_and_its_fk(sph, tmp_path):
    """The turns are program arguments: the file written at ``DESIGN`` (other turning
    lines and joints) has the same structure and, through the same program, the FK of
    the design."""
    path = linkopt.write_design(sph, DESIGN, 10.0, tmp_path / "twisted.toml")
    written = linkopt.load(path)
    assert structure(padded(written)) == structure(padded(sph))
    motors = np.array([[0.1, -0.05], [-0.15, 0.1]])
    ours = linkopt.solve_fk(sph, motors, design=DESIGN).state
    theirs = linkopt.solve_fk(written, motors).state
    np.testing.assert_allclose(theirs, ours, rtol=0, atol=1e-10)


def test_the_partial_gradient_of_link_angles_matches_finite_differences(sph):
    alpha = alpha_minus(sph)
    ev = jax.tree_util.tree_map(np.asarray, evaluate(sph, DESIGN))
    gradient = np.asarray(partial_gradient(sph, DESIGN, ev, alpha))
    objective = jax.jit(
        functools.partial(frozen_objective, sph, evaluation=ev, alpha=alpha)
    )
    h = 1e-5
    fd = [
        (objective(DESIGN + h * e) - objective(DESIGN - h * e)) / (2 * h)
        for e in np.eye(3)
    ]
    assert np.all(np.isfinite(gradient)) and np.abs(fd).max() > 1e-3
    np.testing.assert_allclose(gradient, fd, rtol=1e-5, atol=1e-6 * np.abs(fd).max())


FIVE_BAR = (MECHANISMS / "five_bar.toml").read_text().split("[[parameters]]")[0]


def test_an_offset_is_the_distance_between_parallel_axes():
    mech = parsed(
        FIVE_BAR + '[[parameters]]\nname = "crank"\nkind = "offset"\n'
        'body = "crank_left"\nfrom = "base_left"\nto = "elbow_left"\nmin = 20.0\n'
        "max = 70.0\n"
    )
    index = {n: k for k, n in enumerate(mech.joint_names)}
    assert mech.design.p0[0] == pytest.approx(math.hypot(17.0, 36.0), rel=1e-15)
    anchors = np.asarray(geometry(mech, [55.0]).anchors) * mech.length_scale
    crank = anchors[index["elbow_left"]] - anchors[index["base_left"]]
    assert np.linalg.norm(crank) == pytest.approx(55.0, rel=1e-14)
    np.testing.assert_allclose(
        crank / 55.0,
        [-17.0 / math.hypot(17.0, 36.0), 36.0 / math.hypot(17.0, 36.0), 0.0],
        atol=1e-14,
    )


BASE = TEXT.split("[[parameters]]")[0]


def twist(body, source, target, low, high, name="t") -> str:
    return (
        f'[[parameters]]\nname = "{name}"\nkind = "twist"\nbody = "{body}"\n'
        f'from = "{source}"\nto = "{target}"\nmin = {low}\nmax = {high}\n\n'
    )


MALFORMED = {
    "parallel": (
        FIVE_BAR + twist("crank_left", "base_left", "elbow_left", 0.1, 1.0),
        "parameters[0].to",
        "are parallel at rest and have no twist",
    ),
    "bounds": (
        BASE + twist("link1", "A", "B", 0.5, 3.2),
        "parameters[0].max",
        "a twist lies strictly between 0 and pi",
    ),
    "not_parallel": (
        BASE + twist("link1", "A", "B", 10.0, 60.0).replace("twist", "offset"),
        "parameters[0].to",
        "are not parallel at rest",
    ),
    "moved_linearly": (
        BASE
        + twist("link1", "A", "B", 0.5, 1.2)
        + '[[parameters]]\nname = "a_x"\njoint = "A"\ncoordinate = "x"\n'
        "min = -30.0\nmax = -20.0\n",
        "parameters[0]",
        "joint 'A' of this twist is also moved by a parameter that is not a twist",
    ),
    "one_joint_twice": (
        BASE
        + twist("link1", "A", "B", 0.5, 1.2)
        + twist("link2", "C", "B", 0.5, 1.5, "u"),
        "parameters[1]",
        "drives a coordinate already driven by parameters[0]",
    ),
    "not_on_body": (
        BASE + twist("link1", "A", "C", 0.5, 1.2),
        "parameters[0].to",
        "is not a joint of body 'link1'",
    ),
}


@pytest.mark.parametrize("name", list(MALFORMED))
def test_a_malformed_angle_parameter_names_its_field(name):
    text, where, message = MALFORMED[name]
    with pytest.raises(linkopt.MechanismFileError) as err:
        parsed(text, "bad.toml")
    assert f"bad.toml: {where}" in str(err.value) and message in str(err.value)
