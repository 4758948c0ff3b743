"""Motor limits in the sample searches: projected Newton steps.

Motor limits (``[[motors]]`` ``min``/``max``) make the IK and adversarial searches of
:mod:`linkopt._design.sampling` minimisations over the box of allowed motor values, by
the projected Newton method (Bertsekas, 1982): a motor at a limit whose descent
direction points out of the box is held (its row and column of the model are replaced
by the identity's, its gradient component by zero), the step of the others is solved
as before, and the trial point is clipped into the box. So every sample lies within
the limits, an IK target that needs a motor beyond one is left with a reach residual
(a failure in ``f_design``, as an unreached target), and an adversarial sample
searches only poses the motors can take. A penalty on the excess instead would let
samples stand outside the limits by an amount set by its weight, and clipping alone
(without holding) would stall the others' steps against a limit. The iteration stops
on the projected gradient (a held component counts as zero). Inside the box every
step is the plain one, bit for bit; without limits none of this is traced.
"""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, Bool, Float

from .. import _config  # noqa: F401  (float64 on before any array)
from .._engine.model import Mechanism

#: How close (homogenised) to a motor limit a motor counts as at it: the rounding of
#: a step clipped onto it.
PIN_TOL = 1e-12


def motor_box(mech: Mechanism) -> tuple | None:
    """The motor limits ``(lower, upper)`` in homogenised units (rad, reference
    lengths), ``(M,)`` each (``±inf`` where a motor has none), or None for a file
    without limits (static)."""
    if not mech.motor_limited:
        return None
    scale = mech.motor_scale
    return mech.motor_min / scale, mech.motor_max / scale


def pinned(box, motors, gradient) -> Bool[Array, " M"]:
    """The motors at a limit (within :data:`PIN_TOL`) that the descent direction
    ``-gradient`` pushes out of the box."""
    lower, upper = box
    return ((motors <= lower + PIN_TOL) & (gradient > 0)) | (
        (motors >= upper - PIN_TOL) & (gradient < 0)
    )


def held(box, motors, system, gradient) -> tuple:
    """The step's system ``(M, M)`` and gradient ``(M,)`` with the pinned motors held:
    their rows and columns those of the identity, their gradient zero, so the step
    solved from them leaves those motors where they are."""
    free = ~pinned(box, motors, gradient)
    eye = jnp.eye(motors.shape[0])
    return (
        jnp.where(free[:, None] & free[None, :], system, eye),
        jnp.where(free, gradient, 0.0),
    )


def into_box(box, motors, delta) -> Float[Array, " M"]:
    """``delta`` cut so that ``motors + delta`` stays in the box (exactly ``delta``
    where it does)."""
    return jnp.clip(delta, box[0] - motors, box[1] - motors)


def projected(box, motors, gradient) -> Float[Array, " M"]:
    """The projected gradient: zero where a motor is pinned (the stopping test)."""
    return jnp.where(pinned(box, motors, gradient), 0.0, gradient)
