"""Orientation, displacement and reported outputs, named points, CSV headers by name.

Orientation outputs are the Tait–Bryan angles of one body relative to another
(``R_refᵀ R_body = Rot(e1, roll) Rot(e2, pitch) Rot(e1 × e2, yaw)``), checked by
composing the rotation back from the angles read off random states; their exact
Jacobian rows and those of displacement outputs are checked against ``jax.jacfwd``.
"""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._cli.values import read_values
from linkopt._engine import constraints, jacobian
from linkopt._engine.geometry import geometry
from linkopt._files.fields import parse_toml
from linkopt._files.loader import build

#: Test geometry (not a mechanism whose mobility matches its outputs: built with
#: ``check=False``): an arm on a revolute joint, a plate on a ball joint at its tip and
#: a slider on a prismatic joint along (1, 1, 0).
GIMBAL = """
[mechanism]
name = "gimbal"
ground = "ground"
[[bodies]]
name = "ground"
[[bodies]]
name = "arm"
[[bodies]]
name = "plate"
[[bodies]]
name = "slider"
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
[[joints]]
name = "rail"
type = "prismatic"
bodies = ["ground", "slider"]
anchor = [0.0, 20.0, 0.0]
axis = [1.0, 1.0, 0.0]
[[motors]]
name = "m"
joint = "hinge"
[[outputs]]
name = "roll"
kind = "orientation"
body = "plate"
angle = "roll"
min = -1.0
max = 1.0
[[outputs]]
name = "pitch"
kind = "orientation"
body = "plate"
angle = 2
min = -1.0
max = 1.0
[[outputs]]
name = "yaw"
kind = "orientation"
body = "plate"
angle = "yaw"
min = -1.0
max = 1.0
[[outputs]]
name = "tilt"
kind = "orientation"
body = "plate"
relative_to = "arm"
axis = [0.0, 0.0, 1.0]
axis2 = [0.0, 1.0, 0.0]
angle = 1
min = -1.0
max = 1.0
[[outputs]]
name = "travel"
joint = "rail"
min = -5.0
max = 5.0
[[outputs]]
name = "arm_spin"
kind = "orientation"
body = "arm"
angle = "yaw"
reported = true
"""


def _gimbal(text=GIMBAL):
    return build(parse_toml(text, "gimbal.toml"), "gimbal.toml", check=False)


def _matrix(q):
    w, x, y, z = q / np.linalg.norm(q)
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


def _rot(axis, angle):
    k = np.array(
        [[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]]
    )
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def _random_states(mech, count, seed):
    """Random body positions and unit quaternions near the identity (|pitch| < 90°)."""
    rng = np.random.default_rng(seed)
    bodies = mech.num_bodies
    x = mech.body_origins / mech.length_scale + rng.normal(0, 0.1, (count, bodies, 3))
    q = np.concatenate(
        [np.ones((count, bodies, 1)), rng.normal(0, 0.4, (count, bodies, 3))], -1
    )
    q /= np.linalg.norm(q, axis=-1, keepdims=True)
    q[:, mech.ground] = [1.0, 0.0, 0.0, 0.0]
    x[:, mech.ground] = mech.body_origins[mech.ground] / mech.length_scale
    return np.concatenate([x, q], -1).reshape(count, -1)


def test_orientation_outputs_compose_back_to_the_relative_rotation():
    mech = _gimbal()
    states = _random_states(mech, 20, 0)
    values = np.asarray(linkopt.output_values(mech, states))
    spin = np.asarray(linkopt.reported_values(mech, states))
    worst = 0.0
    for state, out, extra in zip(states, values, spin):
        q = state.reshape(-1, 7)[:, 3:]
        ground, arm, plate = (_matrix(q[k]) for k in range(3))
        x, y, z = np.eye(3)
        composed = _rot(x, out[0]) @ _rot(y, out[1]) @ _rot(z, out[2])
        worst = max(worst, np.abs(composed - ground.T @ plate).max())
        # the "tilt" output: angle 1 in the frame (z, y, z × y = -x) relative to arm
        relative = arm.T @ plate
        e1, e2 = z, y
        e3 = np.cross(e1, e2)
        frame = np.stack([e1, e2, e3], 1)  # columns
        m = frame.T @ relative @ frame  # M_ab = e_a · R e_b
        assert abs(out[3] - np.arctan2(-m[1, 2], m[2, 2])) < 1e-12
        # reported: the arm's yaw about the ground
        assert abs(extra[0] - np.arctan2(-arm[0, 1], arm[0, 0])) < 1e-12
    assert worst < 1e-12


def test_displacement_output_is_the_slide_along_the_joint_axis():
    mech = _gimbal()
    states = _random_states(mech, 10, 1)
    values = np.asarray(linkopt.output_values(mech, states))[:, 4]
    n = np.array([1.0, 1.0, 0.0]) / np.sqrt(2.0)
    anchor = np.array([0.0, 20.0, 0.0])
    for state, value in zip(states, values):
        body = state.reshape(-1, 7)
        xs, rs = body[3, :3] * mech.length_scale, _matrix(body[3, 3:])
        local = anchor - mech.body_origins[3]
        slide = (xs + rs @ local - anchor) @ n  # ground is pinned at the identity
        assert abs(value - slide) < 1e-10
    assert mech.output_scale.tolist() == [1, 1, 1, 1, mech.length_scale]


def test_exact_jacobian_of_the_new_output_rows_matches_forward_mode():
    mech = _gimbal()
    geom = geometry(mech)
    targets = jnp.array([0.1, -0.2, 0.3, 0.05, 0.02])
    forward = jax.jit(
        jax.jacfwd(lambda s: constraints.bk_residual(mech, geom, targets, s))
    )
    for state in _random_states(mech, 4, 2):
        state = jnp.asarray(state)
        value, jac = jacobian.linearise(mech, geom, "bk", targets, state)
        reference = constraints.bk_residual(mech, geom, targets, state)
        dense = forward(state)
        assert np.abs(value - reference).max() < 1e-12
        assert np.abs(jac - dense).max() < 1e-10
        _, hessian, gradient = jacobian.normal_equations(
            mech, geom, "bk", targets, state
        )
        assert np.abs(hessian - dense.T @ dense).max() < 1e-9
        assert np.abs(gradient - dense.T @ reference).max() < 1e-10


@pytest.mark.parametrize(
    "old, new, where, message",
    [
        (
            'name = "travel"\n',
            'name = "travel"\nkind = "speed"\n',
            "outputs[4].kind",
            "unknown output kind 'speed'",
        ),
        (
            'relative_to = "arm"',
            'relative_to = "plate"',
            "outputs[3].relative_to",
            "relative to itself",
        ),
        ('angle = "roll"\n', "", "outputs[0].angle", "missing required field"),
        ('angle = "roll"', 'angle = "heading"', "outputs[0].angle", "'heading'"),
        (
            "axis2 = [0.0, 1.0, 0.0]",
            "axis2 = [0.0, 1.0, 1.0]",
            "outputs[3].axis2",
            "perpendicular",
        ),
        (
            'joint = "rail"',
            'joint = "rail"\nangle = 1',
            "outputs[4].angle",
            "unknown field",
        ),
        (
            'name = "travel"\n',
            'name = "travel"\nkind = "displacement"\n',
            "",
            "",
        ),
        (
            'joint = "rail"',
            'joint = "hinge"\nkind = "displacement"',
            "outputs[4].joint",
            "needs a prismatic or cylindrical joint",
        ),
        (
            'body = "plate"\nangle = "roll"',
            'point = "p"\nangle = "roll"',
            "outputs[0].point",
            "unknown field",
        ),
        ("reported = true", "reported = 1", "outputs[5].reported", "true or false"),
    ],
)
def test_output_fields_are_checked(old, new, where, message):
    text = GIMBAL.replace(old, new, 1)
    assert text != GIMBAL or not message
    if not message:  # accepted: the explicit kind of an inferred displacement
        assert _gimbal(text).output_kinds[4] == "displacement"
        return
    with pytest.raises(linkopt.MechanismFileError, match=message) as err:
        _gimbal(text)
    assert where in str(err.value)


def test_every_output_reported_is_refused_and_a_range_is_optional():
    text = GIMBAL.replace("max = 5.0\n", "max = 5.0\nreported = true\n")
    mech = _gimbal(text)
    assert mech.reported_table.names == ("travel", "arm_spin")
    assert mech.output_names == ("roll", "pitch", "yaw", "tilt")
    only = "\n".join(
        line
        for line in GIMBAL.splitlines()
        if not line.startswith(("min", "max", "reported"))
    ).replace("[[outputs]]\nname", "[[outputs]]\nreported = true\nname")
    with pytest.raises(linkopt.MechanismFileError, match="every output is reported"):
        _gimbal(only)
    missing = GIMBAL.replace("min = -5.0\n", "")
    with pytest.raises(linkopt.MechanismFileError, match=r"outputs\[4\].min"):
        _gimbal(missing)


def test_reported_extras_do_not_count_against_the_mobility(tmp_path):
    four_bar = (MECHANISMS / "four_bar.toml").read_text()
    mech = linkopt.loads(four_bar)
    assert mech.output_names == ("rocker",)
    assert mech.reported_table.names == ("coupler_x", "coupler_y")
    extra = four_bar.replace("reported = true\n", "min = 0.0\nmax = 40.0\n", 1)
    with pytest.raises(linkopt.MechanismFileError, match="mobility 1 .* 2 output"):
        linkopt.loads(extra)
    sol = linkopt.solve_fk(mech, np.array([0.4]))
    point = linkopt.named_points(mech, sol.state)["coupler_point"]
    np.testing.assert_allclose(
        linkopt.reported_values(mech, sol.state), point[:2], atol=1e-12
    )
    np.testing.assert_allclose(
        linkopt.point_positions(mech, sol.state)[0], point, atol=0
    )
    # the writer keeps them: the written file has the same outputs and reads the same
    path = linkopt.write_design(mech, mech.design.p0, 10.0, tmp_path / "w.toml")
    again = linkopt.load(path)
    assert again.reported_table.names == mech.reported_table.names
    np.testing.assert_allclose(
        linkopt.reported_values(again, sol.state),
        linkopt.reported_values(mech, sol.state),
        atol=1e-12,
    )


def test_csv_header_matches_names_in_any_order(tmp_path):
    names = ("x", "y", "z")
    path = tmp_path / "v.csv"
    path.write_text("z,x,y\n3,1,2\n6,4,5\n")
    values, is_path = read_values(str(path), names, "outputs", bounds=[10, 20, 30])
    assert is_path and values.tolist() == [[1, 2, 3], [4, 5, 6]]
    path.write_text("z,x,y\n31,1,2\n")  # bounds follow their column
    with pytest.raises(linkopt.InputError, match="z = 31 is out of range"):
        read_values(str(path), names, "outputs", bounds=[10, 20, 30])
    for header, message in (
        ("z,x,w", "header column 'w' is not one of the outputs"),
        ("z,x", "header lacks the outputs \\['y'\\]"),
        ("z,x,x", "header column 'x' appears twice"),
    ):
        path.write_text(header + "\n1,2,3\n")
        with pytest.raises(linkopt.InputError, match=message):
            read_values(str(path), names, "outputs")


def test_fk_command_prints_the_reported_outputs(capsys):
    import json

    from linkopt._cli.main import main

    path = str(MECHANISMS / "four_bar.toml")
    assert main(["fk", path, "--motors", "0.4", "--json"]) == 0
    record = json.loads(capsys.readouterr().out)
    assert list(record["reported"]) == ["coupler_x", "coupler_y"]
    np.testing.assert_allclose(
        list(record["reported"].values()), record["points"]["coupler_point"][:2]
    )
    assert main(["fk", path, "--motors", "0.4"]) == 0
    assert "  reported coupler_x=" in capsys.readouterr().out
    assert main(["check", path]) == 0
    assert "reported outputs" in capsys.readouterr().out
