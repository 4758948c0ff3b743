"""The Clavel delta of ``mechanisms/delta.toml`` against its closed forms: the file's
geometry, FK as the intersection of three spheres, BK (closed-form arm angles), the
textbook Jacobian ``J_x ṗ = J_q θ̇`` and its singularities."""

import itertools

import delta_closed_form as dc
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._engine.geometry import geometry
from linkopt._engine.jacobian import stacked_jacobians
from linkopt._files.loader import build

MOTORS = np.array(
    [
        [0.0, 0.0, 0.0],
        [0.3, -0.2, 0.5],
        [0.8, 0.6, 0.7],
        [-0.4, 0.2, 0.1],
        [1.0, 0.1, -0.3],
    ]
)
BOX = np.array(list(itertools.product((-50.0, 50.0), (-50.0, 50.0), (-200.0, -140.0))))


@pytest.fixture(scope="module")
def delta():
    return linkopt.load(MECHANISMS / "delta.toml")


def test_file_is_the_closed_form_delta(delta):
    expected = dc.definition()
    anchors = np.array([j["anchor"] for j in expected["joints"]])
    assert delta.joint_names == tuple(j["name"] for j in expected["joints"])
    np.testing.assert_allclose(delta.anchors, anchors, rtol=0, atol=1e-12)
    for start, end in delta.idle_joints:  # every rod 180 mm to rounding
        length = np.linalg.norm(delta.anchors[end] - delta.anchors[start])
        assert length == pytest.approx(dc.SIZES["rod"], abs=1e-12)
    tcp = delta.point_positions[0]
    np.testing.assert_allclose(
        tcp, [0.0, 0.0, -np.sqrt(180.0**2 - 110.0**2)], atol=1e-12
    )


def test_fk_is_the_three_sphere_intersection(delta):
    solution = linkopt.solve_fk(delta, MOTORS)
    assert np.all(np.asarray(solution.converged))
    error = np.asarray(
        linkopt.output_values(delta, solution.state)
    ) - dc.platform_centre(MOTORS)
    assert np.max(np.abs(error)) <= 1e-9


def test_bk_round_trip_gives_back_the_motors(delta):
    outputs = dc.platform_centre(MOTORS[1:])
    solution = linkopt.solve_bk(delta, outputs)
    assert np.all(np.asarray(solution.converged))
    motors = np.asarray(linkopt.motor_values(delta, solution.state))
    np.testing.assert_allclose(motors, MOTORS[1:], atol=1e-9)
    closed = np.stack([dc.arm_angles(p) for p in outputs])
    np.testing.assert_allclose(closed, MOTORS[1:], atol=1e-12)


def _output_jacobian(mech, state) -> np.ndarray:
    """``db/da`` (mm/rad) from ``C_FK`` by the implicit function theorem."""
    jac = np.asarray(stacked_jacobians(mech, geometry(mech), jnp.asarray(state)))[0]
    rhs = np.zeros((jac.shape[0], mech.num_motors))
    rhs[-mech.num_motors :] = np.eye(mech.num_motors)
    ds = np.linalg.solve(jac, rhs).reshape(mech.num_bodies, 7, -1)
    return ds[mech.body_names.index("platform"), :3] * mech.length_scale


def test_output_jacobian_is_the_textbook_one(delta):
    """``ṗ = J_x⁻¹ J_q θ̇``, rows of ``J_x`` the rod vectors, ``J_q`` diagonal."""
    jx, jq = dc.textbook_jacobians(MOTORS)
    for k, a in enumerate(MOTORS):
        textbook = np.linalg.solve(jx[k], np.diag(jq[k]))
        np.testing.assert_allclose(
            _output_jacobian(delta, dc.exact_state(delta, a)),
            textbook,
            rtol=1e-9,
            atol=1e-9,
        )


def _unit_det(motors, sizes=dc.SIZES, rest=dc.REST_ANGLE) -> np.ndarray:
    jx, _ = dc.textbook_jacobians(motors, sizes, rest)
    return np.abs(np.linalg.det(jx / np.linalg.norm(jx, axis=2, keepdims=True)))


def _sigmas(mech, motors, sizes=dc.SIZES, rest=dc.REST_ANGLE) -> np.ndarray:
    states = np.stack([dc.exact_state(mech, a, sizes, rest) for a in motors])
    return np.asarray(linkopt.singular_values(mech, states))


SHORT = dc.SIZES | {"rod": 100.0}  # rods short enough to reach the elbows' plane
LOW = np.radians(60.0)  # arms 60° down at rest


def test_forward_singularity_where_det_jx_vanishes():
    """With 100 mm rods and the arms raised together, the rods turn horizontal, into
    the platform's plane, at ``cos θ = (L_r - R_b + R_p) / L_a``: ``det J_x = 0``
    (like the rods' vertical component, as the square root of the distance to it).
    σ_min of the homogenised FK Jacobian vanishes at the same rate. So does the BK one:
    rods in the platform's plane no longer hold its orientation (a constraint
    singularity that the textbook ``J_x``, written for a level platform, leaves out),
    and the smallest right singular vector is the platform tilting about its centre."""
    mech = build(dc.definition(SHORT, LOW), "short rods")
    assert mech.idle_bodies.size == 6
    theta = np.arccos((SHORT["rod"] - SHORT["base"] + SHORT["platform"]) / SHORT["arm"])
    gaps = np.array([1e-3, 1e-4, 1e-5, 1e-6])
    motors = np.concatenate([[0.0], theta - LOW + gaps])[:, None] * np.ones(3)
    sigma = _sigmas(mech, motors, SHORT, LOW)
    det = _unit_det(motors, SHORT, LOW)
    assert det[-1] < 1e-2 * det[0] and sigma[-1, 0] < 1e-2 * sigma[0, 0]
    slope = sigma[1:, 0] / det[1:]
    np.testing.assert_allclose(slope / slope[-1], 1.0, rtol=1e-2)
    assert sigma[-1, 1] < 1e-2 * sigma[0, 1]
    state = dc.exact_state(mech, motors[-1], SHORT, LOW)
    bk = np.asarray(stacked_jacobians(mech, geometry(mech), jnp.asarray(state)))[1]
    null = np.linalg.svd(bk)[2][-1].reshape(mech.num_bodies, 7)
    platform = null[mech.body_names.index("platform")]
    assert np.linalg.norm(platform[4:6]) > 0.1  # tilt about a horizontal axis
    assert np.linalg.norm(platform[:3]) < 1e-6 and abs(platform[6]) < 1e-6


def test_backward_singularity_leaves_the_fk_jacobian_regular(delta):
    """Arms and rods in line (``J_q = 0``, tested against both deltas in
    test_idle_dofs): the FK σ_min stays well away from zero there."""
    theta = dc.backward_singular_angle()
    sigma = _sigmas(delta, np.array([[0.0] * 3, [theta - 1e-4] * 3]))
    assert sigma[1, 1] < 1e-3 * sigma[0, 1]
    assert sigma[1, 0] > 0.1 * sigma[0, 0]


def test_output_box_is_well_inside_the_workspace(delta):
    """The header's claims at the box corners: closed-form BK exists, ``|det J_x|`` of
    unit rod vectors above 0.45, ``s_i·∂E_i/∂θ_i / (L_a L_r)`` above 0.75, and both
    homogenised σ_min above a third of their rest values."""
    motors = np.stack([dc.arm_angles(p) for p in BOX])
    assert np.all(np.isfinite(motors))
    np.testing.assert_allclose(dc.platform_centre(motors), BOX, atol=1e-10)
    _, jq = dc.textbook_jacobians(motors)
    assert np.all(_unit_det(motors) > 0.45)
    assert np.all(jq / (dc.SIZES["arm"] * dc.SIZES["rod"]) > 0.75)
    sigma = _sigmas(delta, np.concatenate([np.zeros((1, 3)), motors]))
    assert np.all(sigma[1:] > sigma[0] / 3)
