"""Idle degrees of freedom (issue 20, part 4): rods between two ball joints spin about
their own axis without moving anything else. They are found at load, each is fixed by
one gauge row, and the S-S delta then describes the same mechanism as the S-U delta
(a universal joint at one end locks the spin instead)."""

import copy
import json
from functools import partial

import delta_closed_form as dc
import jax
import jax.numpy as jnp
import numpy as np
import pytest
from conftest import MECHANISMS, ROOT

import linkopt
from linkopt._cli.main import main
from linkopt._engine.constraints import bk_residual, fk_residual, passive_residual
from linkopt._engine.geometry import geometry, rest_state
from linkopt._engine.jacobian import linearise, stacked_jacobians
from linkopt._files.loader import build

RODS = ("rod1a", "rod1b", "rod2a", "rod2b", "rod3a", "rod3b")
MOTORS = np.array(
    [[0.3, -0.2, 0.5], [0.8, 0.6, 0.7], [-0.4, 0.2, 0.1], [1.0, 0.1, -0.3]]
)


@pytest.fixture(scope="module")
def ss():
    return linkopt.load(MECHANISMS / "delta.toml")


@pytest.fixture(scope="module")
def su():
    return linkopt.load(ROOT / "tests" / "data" / "delta_su.toml")


def test_ss_delta_is_accepted_with_mobility_3_and_six_idle_rods(ss):
    assert tuple(ss.body_names[b] for b in ss.idle_bodies) == RODS
    for body, (start, end) in zip(ss.idle_bodies, ss.idle_joints):
        assert ss.joint_names[start].startswith("elbow")
        assert ss.joint_names[end].startswith("wrist")
        assert set(ss.joint_bodies[start]) & set(ss.joint_bodies[end]) == {body}
    assert linkopt.mobility(ss) == 3
    # 11 quaternion norms + 6 ground + 3 x 5 revolute + 12 x 3 spherical + 6 gauge.
    assert linkopt.constraint_rows(ss) == {"passive": 74, "fk": 77, "bk": 77}


def test_su_delta_has_no_idle_rod_and_the_same_row_count(su):
    assert su.idle_bodies.size == 0 and su.idle_joints.shape == (0, 2)
    assert linkopt.mobility(su) == 3
    # 6 universal joints (4 rows) replace 6 spherical ones (3 rows) + 6 gauge rows.
    assert linkopt.constraint_rows(su) == {"passive": 74, "fk": 77, "bk": 77}


@partial(jax.jit, static_argnums=0)
def _passive(mech, state):
    return passive_residual(mech, geometry(mech), state)


@partial(jax.jit, static_argnums=0)
def _passive_jacobian(mech, state):
    return jax.jacfwd(lambda s: passive_residual(mech, geometry(mech), s))(state)


def _spin(mech, rod: int) -> np.ndarray:
    """State tangent at rest of rod ``rod`` spinning at 1 rad/s about its own axis
    (its origin, the midpoint of its two anchors, stays put)."""
    start, end = mech.anchors[mech.idle_joints[rod]]
    tangent = np.zeros((mech.num_bodies, 7))
    tangent[mech.idle_bodies[rod], 4:] = (
        0.5 * (end - start) / np.linalg.norm(end - start)
    )
    return tangent.ravel()


def test_gauge_rows_fix_exactly_the_spins(ss):
    jac = np.asarray(_passive_jacobian(ss, rest_state(ss)))
    joints, gauge = jac[:-6], jac[-6:]
    # Without the gauge rows the spins are free: mobility 9, the old refusal.
    assert ss.state_size - np.linalg.matrix_rank(joints, tol=1e-9) == 9
    assert np.linalg.matrix_rank(jac, tol=1e-9) == 74  # gauge independent of the rest
    for k in range(6):
        spin = _spin(ss, k)
        np.testing.assert_allclose(joints @ spin, 0.0, atol=1e-15)
        np.testing.assert_allclose(gauge @ spin, np.eye(6)[k], atol=1e-15)  # unit slope


def test_gauge_row_is_the_twist_of_a_swing_twist_split(ss):
    """``2 v·d = 2 cos(swing/2) sin(twist/2)`` for ``q = q_swing ⊗ q_twist``."""
    rng = np.random.default_rng(3)
    d = ss.anchors[ss.idle_joints[0, 1]] - ss.anchors[ss.idle_joints[0, 0]]
    d /= np.linalg.norm(d)
    for swing, twist in rng.uniform(-2.5, 2.5, size=(5, 2)):
        perp = np.cross(d, rng.standard_normal(3))
        q = dc.quat_mul(
            dc.quat_axis_angle(perp / np.linalg.norm(perp), swing),
            dc.quat_axis_angle(d, twist),
        )
        state = np.array(rest_state(ss)).reshape(-1, 7)
        state[ss.idle_bodies[0], 3:] = q
        value = np.asarray(_passive(ss, jnp.asarray(state.ravel())))
        assert value[-6] == pytest.approx(2 * np.cos(swing / 2) * np.sin(twist / 2))


def test_block_jacobians_with_gauge_rows_match_jacfwd(ss):
    rng = np.random.default_rng(0)
    state = jnp.asarray(dc.exact_state(ss, MOTORS[0]) + 0.05 * rng.standard_normal(77))
    a, b = jnp.asarray(MOTORS[1]), jnp.zeros(3)
    for kind, values in (("fk", a), ("bk", b)):
        (value, jac), (reference, reference_jac) = _both_linearisations(
            ss, kind, values, state
        )
        np.testing.assert_allclose(value, reference, atol=1e-14)
        np.testing.assert_allclose(jac, reference_jac, atol=1e-13)


@partial(jax.jit, static_argnums=(0, 1))
def _both_linearisations(mech, kind, values, state):
    """The block Jacobian's ``(C, ∂C/∂s)`` and jacfwd of ``fk/bk_residual``."""
    geom = geometry(mech)
    residual = fk_residual if kind == "fk" else bk_residual
    reference = (
        residual(mech, geom, values, state),
        jax.jacfwd(lambda s: residual(mech, geom, values, s))(state),
    )
    return linearise(mech, geom, kind, values, state), reference


def _with_rod_point(position) -> dict:
    data = dc.definition()
    data["points"] = data["points"] + [
        {"name": "mark", "body": "rod1a", "position": list(position)}
    ]
    return data


def test_a_point_off_the_axis_makes_the_rod_not_idle():
    data = dc.definition()
    elbow, wrist = (
        np.array(j["anchor"])
        for j in data["joints"]
        if j["name"] in ("elbow1a", "wrist1a")
    )
    on_axis = build(_with_rod_point(0.3 * elbow + 0.7 * wrist), "on", check=False)
    assert on_axis.body_names[on_axis.idle_bodies[0]] == "rod1a"
    off_axis = build(
        _with_rod_point(0.5 * (elbow + wrist) + [0, 0, 1.0]), "off", check=False
    )
    assert tuple(off_axis.body_names[b] for b in off_axis.idle_bodies) == RODS[1:]


def test_an_orientation_output_makes_the_rod_not_idle():
    data = copy.deepcopy(dc.definition())
    data["outputs"].append(
        {
            "name": "spin",
            "kind": "orientation",
            "body": "rod2b",
            "angle": "yaw",
            "reported": True,
        }
    )
    mech = build(data, "orientation", check=False)
    assert "rod2b" not in {mech.body_names[b] for b in mech.idle_bodies}
    assert mech.idle_bodies.size == 5


def test_a_rod_spin_seen_by_a_point_is_refused_with_the_idle_count():
    data = dc.definition()
    elbow, wrist = (
        np.array(j["anchor"])
        for j in data["joints"]
        if j["name"] in ("elbow1a", "wrist1a")
    )
    with pytest.raises(linkopt.MechanismFileError, match=r"mobility 4 .*\(5 idle spin"):
        build(_with_rod_point(0.5 * (elbow + wrist) + [0, 0, 1.0]), "off")


def test_ss_and_su_give_the_same_platform_fk(ss, su):
    positions = []
    for mech in (ss, su):
        solution = linkopt.solve_fk(mech, MOTORS)
        assert np.all(np.asarray(solution.converged))
        positions.append(np.asarray(linkopt.output_values(mech, solution.state)))
    np.testing.assert_allclose(positions[0], positions[1], atol=1e-9)
    np.testing.assert_allclose(positions[0], dc.platform_centre(MOTORS), atol=1e-9)


def _output_jacobian(mech, state) -> np.ndarray:
    """``db/da`` (mm/rad) by the implicit function theorem on ``C_FK``:
    ``J ds = e_m da`` on the motor rows."""
    jac = np.asarray(stacked_jacobians(mech, geometry(mech), jnp.asarray(state)))[0]
    rhs = np.zeros((77, 3))
    rhs[-3:] = np.eye(3)
    ds = np.linalg.solve(jac, rhs).reshape(mech.num_bodies, 7, 3)
    return ds[mech.body_names.index("platform"), :3] * mech.length_scale


def _sigmas(mech, motors) -> np.ndarray:
    states = np.stack([dc.exact_state(mech, a) for a in motors])
    return np.asarray(linkopt.singular_values(mech, states))


def test_ss_and_su_describe_the_same_motion(ss, su):
    """Same ``db/da`` everywhere, and the homogenised σ_min equal to within 2 %: the
    two Jacobians differ only in six rows (gauge ``2 v·d`` vs the universal joint's
    ``(R_arm t)·(R_rod n2)``), both of unit slope in the rod's spin at rest, so the
    σ_min are equal at rest (to 1e-5) and differ slightly elsewhere (by up to 1.0 % at
    these samples), by construction."""
    for a in MOTORS:
        np.testing.assert_allclose(
            _output_jacobian(ss, dc.exact_state(ss, a)),
            _output_jacobian(su, dc.exact_state(su, a)),
            rtol=1e-9,
            atol=1e-9,
        )
    # the rest pose first, in the batch of the samples: one σ_min program each
    motors = np.vstack([np.zeros((1, 3)), MOTORS])
    ratio = _sigmas(ss, motors) / _sigmas(su, motors)
    np.testing.assert_allclose(ratio[0], 1.0, rtol=1e-5)
    np.testing.assert_allclose(ratio[1:], 1.0, rtol=2e-2)


def test_ss_and_su_become_singular_together(ss, su):
    """Towards the backward singularity (arms and rods in line, symmetric motors), the
    BK σ_min of both vanish like the textbook ``s_i·∂E_i/∂θ_i`` and their ratio tends
    to a constant."""
    theta = dc.backward_singular_angle()
    gaps = np.array([1e-1, 1e-2, 1e-3, 1e-4])
    motors = (theta - gaps)[:, None] * np.ones(3)
    # the rest pose last, in the same batch: the same σ_min program
    ss_all = _sigmas(ss, np.vstack([motors, np.zeros((1, 3))]))
    ss_bk, su_bk, rest_bk = ss_all[:-1, 1], _sigmas(su, motors)[:, 1], ss_all[-1, 1]
    _, alignment = dc.textbook_jacobians(motors)
    for sigma in (ss_bk, su_bk):
        slope = sigma / np.abs(alignment[:, 0])
        np.testing.assert_allclose(slope / slope[-1], 1.0, rtol=0.1)
        assert sigma[-1] < 1e-3 * rest_bk
    ratio = ss_bk / su_bk
    np.testing.assert_allclose(ratio / ratio[-1], 1.0, rtol=1e-2)


def test_check_names_the_idle_spins(capsys):
    path = str(MECHANISMS / "delta.toml")
    assert main(["check", path]) == 0
    out = capsys.readouterr().out
    assert (
        "6 idle spin(s): rod1a, rod1b, rod2a, rod2b, rod3a, rod3b spin about their "
        "own axis; fixed by a gauge constraint" in out
    )
    assert main(["check", path, "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["idle_spins"] == list(RODS) and info["mobility"] == 3
