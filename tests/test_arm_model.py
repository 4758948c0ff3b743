"""Serial-arm model: the maximal-coordinate state closes the engine's constraints, and
the tool's pose and Jacobian (from the engine's implicit tangents) match an independent
Denavit–Hartenberg product and the geometric Jacobian ``z_k × (p - o_k)``."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import linkopt  # noqa: F401  (float64)
from linkopt._arms.codesign.model import Module, arm_state, make_arm, tool_rotation
from linkopt._engine.constraints import fk_residual, homogenised_point_positions

# (offset d, length a, twist α) per joint, then the tool length.
DH = [(0.10, 0.30, np.pi / 2), (0.00, 0.25, -0.4), (0.05, 0.20, 1.1)]
TOOL = 0.12


def fixed(v) -> tuple[int, float]:
    """A module slot fixed at ``v`` (no design variable)."""
    return (-1, float(v))


def dh_arm():
    """The arm of ``DH``: twists and lengths of the links are design variables."""
    modules = [
        Module("base", tuple(fixed(v) for v in (0.1, -0.2, 0.3, 0.0, 0.0, 0.0)), 0.0)
    ]
    names, d0 = [], []
    for k, (off, a, alpha) in enumerate(DH):
        modules.append(Module("joint", (), 0.3))
        modules.append(
            Module("link", ((len(d0), a), (len(d0) + 1, alpha), fixed(off)), 0.2)
        )
        names += [f"l{k}", f"t{k}"]
        d0 += [a, alpha]
    modules.append(Module("tool", (fixed(TOOL),), 0.1))
    lower = [v - 1.0 for v in d0]
    upper = [v + 1.0 for v in d0]
    return make_arm(
        "dh", tuple(modules), names, d0, lower, upper, [True, False] * 3, 9.0, 0.02
    )


def _dh_matrix(theta, d, a, alpha):
    ct, st, ca, sa = np.cos(theta), np.sin(theta), np.cos(alpha), np.sin(alpha)
    return np.array(
        [
            [ct, -st * ca, st * sa, a * ct],
            [st, ct * ca, -ct * sa, a * st],
            [0, sa, ca, d],
            [0, 0, 0, 1],
        ]
    )


def dh_reference(theta):
    """Independent closed form: base translation, DH rows, tool
    ``Trans_x · Rot_y(π/2)``; returns the tool pose and the joint frames ``(origin, z)``
    for the geometric Jacobian."""
    t = np.eye(4)
    t[:3, 3] = [0.1, -0.2, 0.3]
    frames = []
    for th, (off, a, alpha) in zip(theta, DH):
        frames.append((t[:3, 3].copy(), t[:3, 2].copy()))
        t = t @ _dh_matrix(th, off, a, alpha)
    tool = np.eye(4)
    tool[0, 3] = TOOL
    tool[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    return t @ tool, frames


@pytest.fixture(scope="module")
def arm():
    return dh_arm()


def test_state_closes_every_constraint(arm):
    theta = jnp.array([0.4, -1.3, 2.2])
    geom, state = jax.jit(arm_state, static_argnums=0)(arm, theta, jnp.asarray(arm.d0))
    assert (
        float(jnp.max(jnp.abs(fk_residual(arm.mechanism, geom, theta, state)))) < 1e-13
    )


@pytest.mark.parametrize(
    "theta", [[0.0, 0.0, 0.0], [0.4, -1.3, 2.2], [-2.9, 0.7, -0.2]]
)
def test_tool_pose_matches_dh_product(arm, theta):
    theta = np.array(theta)
    ref, _ = dh_reference(theta)
    geom, state = jax.jit(arm_state, static_argnums=0)(
        arm, jnp.asarray(theta), jnp.asarray(arm.d0)
    )
    tip = (
        homogenised_point_positions(arm.mechanism, geom, state)[-1]
        * arm.mechanism.length_scale
    )
    np.testing.assert_allclose(tip, ref[:3, 3], atol=1e-12)
    np.testing.assert_allclose(
        tool_rotation(arm, jnp.asarray(theta), jnp.asarray(arm.d0)),
        ref[:3, :3],
        atol=1e-12,
    )


def test_engine_jacobian_matches_geometric_jacobian(arm):
    theta = np.array([0.4, -1.3, 2.2])
    ref, frames = dh_reference(theta)

    @jax.jit
    def tip(th):
        geom, state = arm_state(arm, th, jnp.asarray(arm.d0))
        return (
            homogenised_point_positions(arm.mechanism, geom, state)[-1]
            * arm.mechanism.length_scale
        )

    engine = jax.jit(jax.jacfwd(tip))(jnp.asarray(theta))
    geometric = np.stack([np.cross(z, ref[:3, 3] - o) for o, z in frames], axis=1)
    np.testing.assert_allclose(engine, geometric, atol=1e-10)


def test_design_jacobian_matches_finite_differences(arm):
    theta = jnp.array([0.4, -1.3, 2.2])

    @jax.jit
    def tip(d):
        geom, state = arm_state(arm, theta, d)
        return homogenised_point_positions(arm.mechanism, geom, state)[-1]

    d0 = jnp.asarray(arm.d0)
    engine = jax.jit(jax.jacfwd(tip))(d0)
    h = 1e-6
    fd = np.stack(
        [
            (tip(d0.at[i].add(h)) - tip(d0.at[i].add(-h))) / (2 * h)
            for i in range(d0.size)
        ],
        axis=1,
    )
    np.testing.assert_allclose(engine, fd, atol=1e-8)


def test_one_joint_arm_builds_with_its_span_as_reference_length():
    """A 1-joint arm has a single joint anchor, so the loader cannot infer a reference
    length from anchors (joint elimination reaches such arms); the arm supplies its span
    instead."""
    modules = (
        Module("base", tuple(fixed(v) for v in (0.0, 0.0, 0.3, 0.0, 0.0, 0.0)), 0.0),
        Module("joint", (), 0.3),
        Module("link", ((0, 0.4), fixed(0.0), fixed(0.0)), 0.2),
        Module("tool", (fixed(0.1),), 0.1),
    )
    arm = make_arm("one", modules, ["l"], [0.4], [0.1], [0.6], [True], 9.0, 0.02)
    assert arm.num_joints == 1
    assert arm.mechanism.length_scale == pytest.approx(
        0.5
    )  # anchor at the base to the tool's end
