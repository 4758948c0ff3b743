"""Static motor torques of any mechanism from the constraint multipliers (paper 000,
eq. 7-8).

A mechanism holding constant world forces ``F_l`` at body-fixed points (gravity of point
masses, a payload at the tool) is in equilibrium when the potential
``V(s) = -Σ_l F_l · p_l(s)`` is stationary on the constraint manifold
``C_FK(a, s) = 0``:

    ∇_s V + J_Cᵀ λ = 0,        J_C = ∂C_FK/∂s   (Lagrange multipliers λ).

Differentiating ``V*(a) = V(s(a))`` along the solution gives ``dV*/da = λᵀ ∂C/∂a``; a
motor's row is ``θ(s) - a`` (or ``slide(s) - a`` for a linear motor), so the torque
(force) the motor must supply to hold the pose is ``τ_m = dV*/da_m = -λ_m``
(``-λ_m / length_scale`` for a linear motor, whose row is homogenised). Positive ``τ``
turns the joint's second body in the motor's positive sense. For an open chain
``τ = -Σ_l J_lᵀ F_l`` (``J_l`` the Jacobian of point ``l``), i.e. the textbook
``τ = Jᵀ F`` with ``F`` the force the arm exerts on the load.

The passive rows of a closed loop may be redundant (``J_C`` tall, rank-deficient); the
multipliers are then not unique, but their motor part is whenever the motors are
independent, and the minimum-norm solution (pseudo-inverse) gives it. A square ``J_C``
(a serial chain) is solved directly, which is exact and cheaper to differentiate.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import InputError
from . import dense, dense_lu
from .constraints import body_frames
from .geometry import Geometry, design_vector, geometry
from .jacobian import state_jacobian
from .model import Mechanism
from .rotations import rotate


def load_potential(
    mech: Mechanism, geom: Geometry, state, bodies: np.ndarray, points, forces
) -> Float[Array, ""]:
    """``V(s) = -Σ F_l · p_l(s)`` (force × file length) for forces ``(L, 3)`` at rest
    points ``(L, 3)`` (file units, world frame at the rest pose) fixed in
    ``bodies (L,)``."""
    x, q = body_frames(state)
    scale = mech.length_scale
    local = jnp.asarray(points) / scale - geom.origins[bodies]
    world = (x[bodies] + rotate(q[bodies], local)) * scale
    return -jnp.sum(jnp.asarray(forces) * world)


def multipliers(
    mech: Mechanism, geom: Geometry, state, bodies: np.ndarray, points, forces
) -> Float[Array, " R"]:
    """Constraint multipliers ``λ`` of ``J_Cᵀ λ = -∇V`` at a solved FK state (module
    docstring)."""
    grad = jax.grad(load_potential, argnums=2)(
        mech, geom, state, bodies, points, forces
    )
    jac = state_jacobian(mech, geom, "fk", state)
    if jac.shape[0] == jac.shape[1]:
        return dense_lu.solve(jac.T, -grad)
    # least-norm λ = -J (JᵀJ)⁻¹ ∇V = -pinv(Jᵀ) ∇V for J of full column rank (a solved,
    # non-singular FK state); by Cholesky rather than LAPACK's SVD (linkopt._config)
    return -jac @ dense.solve_spd(jac.T @ jac, grad)


def motor_torques(
    mech: Mechanism, geom: Geometry, state, bodies: np.ndarray, points, forces
) -> Float[Array, " M"]:
    """Static motor torques ``τ = -λ_motors`` (N·file length, or N for linear
    motors)."""
    lam = multipliers(mech, geom, state, bodies, points, forces)
    return -lam[-mech.num_motors :] / jnp.asarray(mech.motor_scale)


def static_torques(
    mech: Mechanism, state, bodies, points, forces, *, design=None
) -> Float[Array, " M"]:
    """Motor torques (forces) that hold ``state`` against constant world
    ``forces (L, 3)`` applied at ``points (L, 3)`` (rest positions, file units) of
    ``bodies`` (``L`` names or indices); e.g. gravity ``m_l g`` of point masses, or a
    payload at the tool.

    Works for any mechanism, closed loops included; ``state`` must be a solved FK state
    (homogenised), ``design`` the design it was solved for.
    """
    for b in bodies:
        if isinstance(b, str) and b not in mech.body_names:
            raise InputError(
                f"static_torques: unknown body {b!r}; expected one of "
                f"{list(mech.body_names)}"
            )
    index = np.array(
        [mech.body_names.index(b) if isinstance(b, str) else int(b) for b in bodies],
        dtype=int,
    )
    geom = geometry(mech, design_vector(mech, design))
    state = jnp.asarray(state, dtype=jnp.float64)
    points = jnp.asarray(points, dtype=jnp.float64).reshape(-1, 3)
    forces = jnp.asarray(forces, dtype=jnp.float64).reshape(-1, 3)
    return motor_torques(mech, geom, state, index, points, forces)
