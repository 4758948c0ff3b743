"""Static torques from the constraint multipliers (J_Cᵀλ = -∇V): a 2-link planar arm
under gravity and payload against the textbook ``τ = Jᵀ F``, and a closed-loop five-bar
against the principle of virtual work with finite-difference FK solves."""

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import linkopt
from linkopt._arms.codesign.model import Module, arm_loads, arm_state, make_arm
from linkopt._engine.statics import motor_torques, static_torques

ROOT = Path(__file__).resolve().parent.parent
L1, L2, M1, M2, MJ, MP, G = 0.4, 0.3, 1.5, 0.8, 0.35, 0.6, 9.81


def fixed(v) -> tuple[int, float]:
    """A module slot fixed at ``v`` (no design variable)."""
    return (-1, float(v))


def planar_arm():
    """Two vertical axes (z) in the xy-plane, gravity along -y; links' masses at their
    midpoints, the elbow actuator's mass at the elbow, the payload at the tip."""
    modules = (
        Module("base", tuple(fixed(0.0) for _ in range(6)), 0.0),
        Module("joint", (), 0.0),
        Module("link", ((0, L1), fixed(0.0), fixed(0.0)), M1),
        Module("joint", (), MJ),
        Module("link", ((1, L2), fixed(0.0), fixed(0.0)), M2),
        Module("tool", (fixed(0.0),), 0.0),
    )
    return make_arm(
        "planar",
        modules,
        ["l1", "l2"],
        [L1, L2],
        [0.1, 0.1],
        [1.0, 1.0],
        [True, True],
        9.0,
        0.02,
    )


@pytest.fixture(scope="module")
def arm():
    return planar_arm()


@pytest.mark.parametrize("theta", [[0.3, 0.5], [-1.1, 2.0], [np.pi / 2, 0.0]])
def test_planar_arm_matches_jacobian_transpose(arm, theta):
    c1, c12 = np.cos(theta[0]), np.cos(theta[0] + theta[1])
    s1, s12 = np.sin(theta[0]), np.sin(theta[0] + theta[1])

    @jax.jit
    def torques(th):
        d = jnp.asarray(arm.d0)
        geom, state = arm_state(arm, th, d)
        return motor_torques(
            arm.mechanism, geom, state, *arm_loads(arm, d, [0.0, -G, 0.0], MP)
        )

    tau = np.asarray(torques(jnp.asarray(theta)))
    # Point Jacobians (xy rows) of the link midpoints, elbow and tip, and the loads on
    # them.
    jac = {
        "m1": np.array([[-0.5 * L1 * s1, 0.0], [0.5 * L1 * c1, 0.0]]),
        "elbow": np.array([[-L1 * s1, 0.0], [L1 * c1, 0.0]]),
        "m2": np.array(
            [
                [-L1 * s1 - 0.5 * L2 * s12, -0.5 * L2 * s12],
                [L1 * c1 + 0.5 * L2 * c12, 0.5 * L2 * c12],
            ]
        ),
        "tip": np.array(
            [[-L1 * s1 - L2 * s12, -L2 * s12], [L1 * c1 + L2 * c12, L2 * c12]]
        ),
    }
    mass = {"m1": M1, "elbow": MJ, "m2": M2, "tip": MP}
    # τ = Σ Jᵀ F with F the force the arm exerts on each load (holding it up: +m g ŷ).
    expected = sum(jac[k].T @ np.array([0.0, mass[k] * G]) for k in jac)
    np.testing.assert_allclose(tau, expected, atol=1e-10)
    closed = [
        G
        * (
            M1 * L1 / 2 * c1
            + MJ * L1 * c1
            + M2 * (L1 * c1 + L2 / 2 * c12)
            + MP * (L1 * c1 + L2 * c12)
        ),
        G * c12 * (M2 * L2 / 2 + MP * L2),
    ]
    np.testing.assert_allclose(tau, closed, atol=1e-10)


def test_closed_loop_five_bar_obeys_virtual_work():
    mech = linkopt.load(ROOT / "mechanisms" / "five_bar.toml")
    motors = np.array([0.15, -0.1])
    state = linkopt.solve_fk(mech, motors).state
    force = np.array([3.0, -2.0, 0.0])
    rest_ee = mech.point_positions[mech.point_names.index("ee")]
    tau = np.asarray(
        static_torques(mech, state, ["distal_left"], rest_ee[None], force[None])
    )
    h = 1e-6

    def ee(a):
        solution = linkopt.solve_fk(mech, a, start=state)
        return np.asarray(linkopt.point_positions(mech, solution.state))[0]

    dp_da = np.stack(
        [(ee(motors + h * e) - ee(motors - h * e)) / (2 * h) for e in np.eye(2)], axis=1
    )
    np.testing.assert_allclose(tau, -dp_da.T @ force, rtol=1e-6, atol=1e-8)
