"""The rest pose's conditioning: the input-output Jacobian at rest, its smallest
singular value, and ``alpha_minus`` (the f_sing threshold below which a design is
singular, paper Sec. IV), with the message that names a near-singular rest pose.
"""

from __future__ import annotations

import weakref
from dataclasses import dataclass

import numpy as np
from jaxtyping import Float

from .._engine.mobility import rest_jacobians
from .._engine.model import Mechanism
from .._errors import MechanismFileError

#: σ_min (homogenised, FK or BK) at the rest pose below which ``linkopt check`` warns
#: and :func:`alpha_minus` refuses to derive α₋ (f_sing ≥ 1e3 there). Our choice: the
#: shipped mechanisms' rest poses have σ_min 0.035-0.26 (f_sing 8-42), 35x or more
#: above it; the loader refuses a rest pose as singular only below 1e-7
#: (:mod:`linkopt._engine.mobility`).
NEAR_SINGULAR_SIGMA = 1e-3


@dataclass(frozen=True)
class RestConditioning:
    """The initial design's rest pose: homogenised ``σ_min`` of ``∂C_FK/∂s`` and
    ``∂C_BK/∂s`` (eq. 3), and the singular values of the textbook input-output
    Jacobian ``J = ∂b/∂a`` in file units (descending; file units per rad for rotary
    motors and Cartesian outputs)."""

    sigma_fk: float
    sigma_bk: float
    jacobian_sigmas: np.ndarray  # (min(K, M),)

    @property
    def f_sing(self) -> float:
        return 1.0 / self.sigma_fk + 1.0 / self.sigma_bk

    @property
    def near_singular(self) -> bool:
        return not (  # NaN counts as near
            self.sigma_fk >= NEAR_SINGULAR_SIGMA
            and self.sigma_bk >= NEAR_SINGULAR_SIGMA
        )

    def as_json(self) -> dict:
        """What ``linkopt check`` and ``evaluate`` report as ``rest_pose``."""
        return {
            "sigma_min_fk": self.sigma_fk,
            "sigma_min_bk": self.sigma_bk,
            "f_sing": self.f_sing,
            "jacobian_sigma_min": float(self.jacobian_sigmas[-1]),
            "jacobian_sigma_max": float(self.jacobian_sigmas[0]),
            "near_singular": self.near_singular,
        }


def input_output_jacobian(
    mech: Mechanism, jac_fk: Float[np.ndarray, "R S"], jac_bk: Float[np.ndarray, "R S"]
) -> Float[np.ndarray, "K M"]:
    """``∂b/∂a`` in file units from the homogenised constraint Jacobians: the state
    velocity of a unit motor velocity solves ``∂C_FK/∂s ṡ = (0, e_i)`` (motor rows
    last, unit slope), the outputs' velocity is the output rows of ``∂C_BK/∂s`` times
    ``ṡ``; then ``J = diag(output_scale) J_hom diag(1 / motor_scale)``."""
    m, k = mech.num_motors, mech.num_outputs
    rhs = np.zeros((jac_fk.shape[0], m))
    rhs[-m:] = np.eye(m)
    velocity = np.linalg.lstsq(jac_fk, rhs, rcond=None)[0]
    homogenised = jac_bk[-k:] @ velocity
    return mech.output_scale[:, None] * homogenised / mech.motor_scale[None, :]


def rest_conditioning(mech: Mechanism) -> RestConditioning:
    """:class:`RestConditioning` of the file's initial design."""
    rest = rest_jacobians(mech)
    if rest.rates is not None:  # on the band: no dense Jacobian formed
        rates = np.asarray(rest.rates)
        jac = mech.output_scale[:, None] * rates / mech.motor_scale[None, :]
    else:
        jac_fk, jac_bk = rest.stacked
        jac = input_output_jacobian(mech, np.asarray(jac_fk), np.asarray(jac_bk))
    sigma_fk, sigma_bk = (float(v) for v in np.asarray(rest.sigmas))
    return RestConditioning(sigma_fk, sigma_bk, np.linalg.svd(jac, compute_uv=False))


#: α₋ of each live mechanism: weak, so that a mechanism dropped by its caller is not
#: kept alive by having been evaluated once.
_ALPHA_MINUS: weakref.WeakKeyDictionary[Mechanism, float] = weakref.WeakKeyDictionary()


def alpha_minus(mech: Mechanism) -> float:
    """``α₋ = alpha_factor · f_sing(rest pose of the initial design)``, unless the file
    gives ``alpha_minus`` itself. Computed once per mechanism while it lives.

    :class:`~linkopt.MechanismFileError` when the rest pose is near a singularity
    (σ_min below :data:`NEAR_SINGULAR_SIGMA`): α₋ would then be huge (σ_min 8e-6 gave
    4.6e5) and ``f_design`` would report no singularity however close a design came;
    the file must set ``[evaluation] alpha_minus``."""
    if mech.evaluation.alpha_minus is not None:
        return float(mech.evaluation.alpha_minus)
    if mech not in _ALPHA_MINUS:
        _ALPHA_MINUS[mech] = _alpha_from_rest(mech)
    return _ALPHA_MINUS[mech]


def _alpha_from_rest(mech: Mechanism) -> float:
    rest = rest_conditioning(mech)
    if rest.near_singular:
        raise MechanismFileError(
            mech.source, "[evaluation].alpha_minus", near_singular_message(mech, rest)
        )
    return float(mech.evaluation.alpha_factor * rest.f_sing)


def near_singular_message(mech: Mechanism, rest: RestConditioning) -> str:
    """Why α₋ is not derived from this rest pose, and what to do (one line)."""
    which = "forward" if rest.sigma_fk <= rest.sigma_bk else "backward"
    return (
        f"the rest pose is near a {which} singularity (σ_min FK {rest.sigma_fk:.2g}, "
        f"BK {rest.sigma_bk:.2g}, below {NEAR_SINGULAR_SIGMA:g}; f_sing "
        f"{rest.f_sing:.3g}), so alpha_factor x f_sing = "
        f"{mech.evaluation.alpha_factor * rest.f_sing:.3g} would hide singularities; "
        "set [evaluation] alpha_minus explicitly (the shipped mechanisms use 16-85), "
        "or move the rest pose away from the singularity"
    )
