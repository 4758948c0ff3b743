"""Direction outputs (issue 45): the tilt of a body's axis ``d`` relative to another
body as two angles, the components along ``e1 = axis2`` and ``e2 = d × e1`` of the
rotation vector of the shortest rotation taking ``d`` to ``R_refᵀ R_body d``.

Checked against the closed form (a swing by θ about a unit ``w ⟂ d`` after any spin
about ``d`` reads ``θ (w·e1, w·e2)``), their exact Jacobian rows against forward mode
and central finite differences (at rest too, where ``θ / sin θ`` is a series), a BK
solve of a spherical five-bar whose outputs are its tip axis's two tilts (checked
against the five-bar's closed form), the ``fk``/``bk`` commands, and the load errors.
"""

import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from test_assembly_spherical import ARCS, rest_axes
from test_assembly_spherical import drawing as spherical_drawing
from test_outputs_orientation import _matrix, _random_states, _rot

import linkopt
from linkopt._engine import constraints, jacobian
from linkopt._engine.geometry import geometry
from linkopt._files.assembly import assemble
from linkopt._files.fields import parse_toml
from linkopt._files.loader import build
from linkopt._files.outputs import default_tilt_axis
from linkopt._files.writer import dumps

#: Test geometry (built with ``check=False``): an arm on a revolute joint and a plate
#: on a ball joint at its tip; the plate's axis (1, 0, 2)/√5 read as a direction
#: relative to the ground (default axis2) and relative to the arm (axis2 given).
POINTER = """
[mechanism]
name = "pointer"
ground = "ground"
[[bodies]]
name = "ground"
[[bodies]]
name = "arm"
[[bodies]]
name = "plate"
[[joints]]
name = "hinge"
type = "revolute"
bodies = ["ground", "arm"]
anchor = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "ball"
type = "spherical"
bodies = ["arm", "plate"]
anchor = [30.0, 0.0, 10.0]
[[motors]]
name = "m"
joint = "hinge"
[[outputs]]
name = "tilt_1"
kind = "direction"
body = "plate"
axis = [1.0, 0.0, 2.0]
angle = 1
min = -1.0
max = 1.0
[[outputs]]
name = "tilt_2"
kind = "direction"
body = "plate"
axis = [1.0, 0.0, 2.0]
angle = 2
min = -1.0
max = 1.0
[[outputs]]
name = "on_arm"
kind = "direction"
body = "plate"
relative_to = "arm"
axis = [0.0, 0.0, 1.0]
axis2 = [0.0, 1.0, 0.0]
angle = 2
reported = true
"""
D = np.array([1.0, 0.0, 2.0]) / np.sqrt(5.0)


def _pointer(text=POINTER):
    return build(parse_toml(text, "pointer.toml"), "pointer.toml", check=False)


def _quaternion(r):
    """``wxyz`` of a rotation matrix (through scipy, independent of linkopt)."""
    from scipy.spatial.transform import Rotation

    x, y, z, w = Rotation.from_matrix(r).as_quat()
    return np.array([w, x, y, z])


def _state(mech, plate, arm=None):
    """Rest positions, the arm (None: at rest) and the plate turned by the given
    matrices."""
    arm = np.eye(3) if arm is None else arm
    body = np.zeros((mech.num_bodies, 7))
    body[:, :3] = mech.body_origins / mech.length_scale
    body[:, 3] = 1.0
    body[1, 3:] = _quaternion(arm)
    body[2, 3:] = _quaternion(plate)
    return body.reshape(-1)


def _tilt(v, d, e1):
    """The definition, directly: rotation vector of the shortest rotation d → v."""
    axis = np.cross(d, v)
    theta = np.arctan2(np.linalg.norm(axis), d @ v)
    w = axis / np.linalg.norm(axis) if np.linalg.norm(axis) else axis
    return theta * np.array([w @ e1, w @ np.cross(d, e1)])


def test_default_first_tilt_axis():
    np.testing.assert_allclose(default_tilt_axis(np.array([0.0, 0, 1])), [1, 0, 0])
    np.testing.assert_allclose(default_tilt_axis(D), [0, 1, 0])  # y: least aligned
    mech = _pointer()
    np.testing.assert_allclose(mech.output_table.frames[0], [D, [0, 1, 0]], atol=1e-15)


def test_swing_after_a_spin_reads_its_angle_components():
    """Closed form: ``R = Rot(w, θ) Rot(d, γ)`` (w ⟂ d) reads ``θ (w·e1, w·e2)``
    whatever the spin γ; a spin alone reads zero, rest reads zero."""
    mech = _pointer()
    e1 = np.array([0.0, 1.0, 0.0])
    e2 = np.cross(D, e1)
    rng = np.random.default_rng(0)
    states, expected = [], []
    for theta in (0.0, 1e-9, 1e-5, 0.3, -1.2, 2.5, 3.0):
        phi, gamma = rng.uniform(-np.pi, np.pi, 2)
        w = np.cos(phi) * e1 + np.sin(phi) * e2
        states.append(_state(mech, _rot(w, theta) @ _rot(D, gamma)))
        expected.append(theta * np.array([np.cos(phi), np.sin(phi)]))
    values = np.asarray(linkopt.output_values(mech, np.array(states)))
    np.testing.assert_allclose(values, expected, rtol=0, atol=1e-12)
    # about e1 alone: (α, 0); about e2 alone: (0, α)
    for k, e in enumerate((e1, e2)):
        got = np.asarray(linkopt.output_values(mech, _state(mech, _rot(e, 0.4))))
        np.testing.assert_allclose(got, 0.4 * np.eye(2)[k], atol=1e-14)


def test_relative_to_another_body_and_reported():
    """The reported tilt of the plate's z axis relative to the arm (e1 = y, e2 = z ×
    y = -x) is the definition applied to ``R_armᵀ R_plate z``."""
    mech = _pointer()
    z, y = np.eye(3)[2], np.eye(3)[1]
    for state in _random_states(mech, 10, 3):
        q = state.reshape(-1, 7)[:, 3:]
        arm, plate = _matrix(q[1]), _matrix(q[2])
        got = np.asarray(linkopt.reported_values(mech, state))[0]
        assert abs(got - _tilt(arm.T @ plate @ z, z, y)[1]) < 1e-12
        values = np.asarray(linkopt.output_values(mech, state))
        np.testing.assert_allclose(values, _tilt(plate @ D, D, y), atol=1e-12)


def _near_rest_states(mech):
    """Rest, tilts of 1e-9 and 1e-7 rad (the series branch and just past it) and a
    random state."""
    w = np.array([0.3, 0.8, -0.52])
    return [
        _state(mech, np.eye(3), _rot(np.eye(3)[2], 0.2)),
        _state(mech, _rot(w / np.linalg.norm(w), 1e-9)),
        _state(mech, _rot(w / np.linalg.norm(w), 1e-7)),
        *_random_states(mech, 2, 4),
    ]


def test_exact_jacobian_matches_forward_mode_and_finite_differences():
    mech = _pointer()
    geom = geometry(mech)
    targets = jnp.array([0.1, -0.2])
    forward = jax.jit(
        jax.jacfwd(lambda s: constraints.bk_residual(mech, geom, targets, s))
    )
    values = jax.jit(lambda s: constraints.homogenised_output_values(mech, geom, s))
    # jitted, as the solvers run them: op by op, the closed form's small operations
    # compiled one by one (about 280 compilations)
    linearised = jax.jit(lambda s: jacobian.linearise(mech, geom, "bk", targets, s))
    residual = jax.jit(lambda s: constraints.bk_residual(mech, geom, targets, s))
    exact_of = jax.jit(jax.jacfwd(values))
    for state in _near_rest_states(mech):
        state = jnp.asarray(state)
        value, jac = linearised(state)
        dense = forward(state)
        assert np.all(np.isfinite(dense))
        assert np.abs(value - residual(state)).max() < 1e-12
        assert np.abs(jac - dense).max() < 1e-10
        # central differences of the two angles, every state entry
        step = 1e-6
        fd = np.stack(
            [
                (values(state.at[i].add(step)) - values(state.at[i].add(-step)))
                / (2 * step)
                for i in range(state.size)
            ],
            axis=1,
        )
        exact = exact_of(state)
        assert np.abs(exact - fd).max() < 1e-7
        assert np.abs(dense[-2:] - exact).max() < 1e-12  # the output rows


@pytest.fixture(scope="module")
def five_bar_pointing():
    """The spherical five-bar whose outputs are the two tilts of its tip axis C
    (on link2), relative to the ground, ±0.3 rad."""
    text = spherical_drawing()
    text = text[: text.index("\n[[outputs]]")]
    c = ", ".join(repr(float(v)) for v in rest_axes()["C"])
    for k in (1, 2):
        text += (
            f'\n[[outputs]]\nname = "tilt_{k}"\nkind = "direction"\nbody = "link2"\n'
            f"axis = [{c}]\nangle = {k}\nmin = -0.3\nmax = 0.3\n"
        )
    result = assemble(parse_toml(text, "sph.toml"), "sph.toml")
    return linkopt.loads(dumps(result.data), "spherical_pointing.toml")


def _five_bar_tip(a1, a2):
    """Closed form of the spherical five-bar's tip axis for motor angles (a1, a2)."""
    from test_assembly_spherical import tip

    n = rest_axes()
    y = np.array([0.0, 1.0, 0.0])
    cos, sin = np.cos(np.radians(ARCS)), np.sin(np.radians(ARCS))
    b = _rot(n["A"], a1) @ (cos[0] * n["A"] + sin[0] * y)
    d = _rot(n["E"], a2) @ (cos[3] * n["E"] + sin[3] * y)
    return tip(b, d)


def test_bk_on_a_spherical_five_bar_reaches_the_tilts(five_bar_pointing):
    """Closed form: the tilts of the tip axis that the five-bar's closed form gives
    for motor angles ``a`` are BK targets whose solution has the motors ``a`` back
    and reads the targets; the BK sensitivity ``ds/db`` (JAX, implicit) matches
    central differences of BK solves."""
    mech = five_bar_pointing
    c0 = rest_axes()["C"]
    e1 = mech.output_table.frames[0, 1]
    motors = np.array([[0.15, -0.1], [-0.2, 0.12], [0.1, 0.2]])
    targets = np.array([_tilt(_five_bar_tip(*a), c0, e1) for a in motors])
    assert np.all(np.abs(targets) < 0.3) and np.abs(targets).min() > 1e-3
    # row by row: the one-row program that the bk command below runs too (a batch
    # would compile the 64-row block's program beside it)
    solved = [linkopt.solve_bk(mech, row) for row in targets]
    assert all(bool(sol.converged) for sol in solved)
    states = np.stack([np.asarray(sol.state) for sol in solved])
    np.testing.assert_allclose(linkopt.output_values(mech, states), targets, atol=1e-9)
    np.testing.assert_allclose(linkopt.motor_values(mech, states), motors, atol=1e-9)
    state = states[0]
    exact = np.asarray(linkopt.sensitivity(mech, state, "outputs"))
    step = 1e-6
    fd = np.stack(
        [
            (
                np.asarray(linkopt.solve_bk(mech, targets[0] + h, start=state).state)
                - np.asarray(linkopt.solve_bk(mech, targets[0] - h, start=state).state)
            )
            / (2 * step)
            for h in step * np.eye(2)
        ],
        axis=1,
    )
    assert np.abs(exact - fd).max() < 1e-6


def test_fk_and_bk_commands_print_the_tilts(five_bar_pointing, tmp_path, capsys):
    from linkopt._cli.main import main
    from linkopt._files.writer import dumps as write

    path = tmp_path / "pointing.toml"
    path.write_text(write(five_bar_pointing.raw))
    assert main(["bk", str(path), "--outputs", "0.1,-0.05"]) == 0
    out = capsys.readouterr().out
    assert "converged=True" in out and "tilt_1=0.1" in out and "tilt_2=-0.05" in out
    assert main(["fk", str(path), "--motors", "0.15,-0.1", "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    frame = five_bar_pointing.output_table.frames[0]
    expected = _tilt(_five_bar_tip(0.15, -0.1), frame[0], frame[1])
    np.testing.assert_allclose(list(record["outputs"].values()), expected, atol=1e-9)
    assert list(record["outputs"]) == ["tilt_1", "tilt_2"]
    assert main(["check", str(path), "--json"]) == 0
    outputs = json.loads(capsys.readouterr().out)["outputs"]
    assert outputs["tilt_2"] == {"kind": "direction", "min": -0.3, "max": 0.3}


@pytest.mark.parametrize(
    "old, new, where, message",
    [
        (
            "axis = [1.0, 0.0, 2.0]\nangle = 1\n",
            "angle = 1\n",
            "outputs[0].axis",
            "missing required field for a direction",
        ),
        (
            "angle = 1\n",
            "",
            "outputs[0].angle",
            "missing required field for a direction",
        ),
        ("angle = 1\n", "angle = 3\n", "outputs[0].angle", "from 1 to 2, got 3"),
        (
            "axis = [1.0, 0.0, 2.0]\nangle = 1",
            "axis = [0.0, 0.0, 0.0]\nangle = 1",
            "outputs[0].axis",
            "zero-length",
        ),
        (
            "axis2 = [0.0, 1.0, 0.0]",
            "axis2 = [0.0, 1.0, 1.0]",
            "outputs[2].axis2",
            "perpendicular",
        ),
        (
            'relative_to = "arm"',
            'relative_to = "plate"',
            "outputs[2].relative_to",
            "direction of 'plate' relative to itself",
        ),
        (
            'body = "plate"\naxis = [1.0',
            'body = "plate"\npoint = "p"\naxis = [1.0',
            "outputs[0].point",
            "a direction output",
        ),
        (
            'body = "plate"\naxis = [1.0',
            'body = "nowhere"\naxis = [1.0',
            "outputs[0].body",
            "nowhere",
        ),
    ],
)
def test_direction_fields_are_checked(old, new, where, message):
    text = POINTER.replace(old, new, 1)
    assert text != POINTER
    with pytest.raises(linkopt.MechanismFileError, match=message) as err:
        _pointer(text)
    assert where in str(err.value)
