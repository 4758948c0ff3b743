"""Partial gradient of the design objective (paper Sec. V).

``∂/∂p [f_design + regulariser]`` with the IK and adversarial motor values *frozen*:
each sample's state is re-solved by forward kinematics at its frozen motors for the
design ``p`` (warm-started at the sample's state, so no iterations are needed at the
evaluated design) and differentiated through the implicit function theorem at fixed
motors, ``ds/dp = -(JᵀJ)⁻¹ Jᵀ ∂C_FK/∂p``. The singularity term's dependence on ``p``
also enters directly through the Jacobians (``σ = uᵀ J(s, p) v``).
"""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp

from ._constraints import output_residual
from ._evaluation import Evaluation, regularizer, targets
from ._geometry import geometry
from ._kinematics import _solve_single
from ._metrics import culled, thresholds
from ._model import Mechanism
from ._singularity import f_sing_value


def frozen_objective(mech: Mechanism, design, evaluation: Evaluation, alpha) -> jax.Array:
    """``f_design + regulariser`` at ``design`` with the samples' motors held fixed."""
    geom = geometry(mech, design)
    th = thresholds(alpha)
    goals = jnp.asarray(targets(mech) / mech.output_scale)

    def reach(goal, motors, start):
        state = _solve_single(mech, "fk", geom, motors, start).state
        residual = output_residual(mech, geom, goal, state)
        return 0.5 * residual @ residual

    def singular(motors, start):
        state = _solve_single(mech, "fk", geom, motors, start).state
        return culled(f_sing_value(mech, geom, state), th)

    motors_ik = jax.lax.stop_gradient(evaluation.ik_motors)
    motors_adv = jax.lax.stop_gradient(evaluation.adv_motors)
    f_reach = jax.vmap(reach)(goals, motors_ik, jax.lax.stop_gradient(evaluation.ik_states))
    f_sing = jax.vmap(singular)(motors_adv, jax.lax.stop_gradient(evaluation.adv_states))
    return jnp.mean(f_reach + f_sing) + regularizer(mech, design)


@partial(jax.jit, static_argnums=0)
def _gradients(mech: Mechanism, designs, evaluation: Evaluation, alpha):
    grad = jax.grad(lambda p, ev: frozen_objective(mech, p, ev, alpha))
    if designs.ndim == 1:
        return grad(designs, evaluation)
    return jax.vmap(grad)(designs, evaluation)


def partial_gradient(mech: Mechanism, designs, evaluation: Evaluation, alpha: float):
    """Partial gradients ``(n_p,)`` or ``(N, n_p)`` for designs evaluated as ``evaluation``."""
    return _gradients(mech, jnp.asarray(designs, dtype=jnp.float64), evaluation, alpha)
