"""Mobility at the rest pose and the load-time checks that depend on it."""

from __future__ import annotations

import jax
import numpy as np

from .._errors import MechanismFileError
from . import programs
from .constraints import passive_residual
from .geometry import geometry, rest_state
from .model import Mechanism
from .singularity import sigma_min_pair

RANK_TOL = 1e-9  # relative to the largest singular value
SINGULAR_TOL = (
    1e-7  # absolute σ_min (homogenised) below which the rest pose is singular
)


def _passive_jacobian(mech: Mechanism):
    def program(mech):
        geom = geometry(mech)
        return jax.jacfwd(lambda s: passive_residual(mech, geom, s))(rest_state(mech))

    return programs.call("passive_jacobian", mech, program)


def _rest_sigmas(mech: Mechanism):
    """σ_min of the rest pose (a program whose trace is kept on disk, as every load
    runs it: :mod:`.programs`)."""
    return programs.call(
        "rest_sigmas",
        mech,
        lambda m: sigma_min_pair(m, geometry(m), rest_state(m)),
    )


def mobility(mech: Mechanism) -> int:
    """Degrees of freedom at rest: ``|s| - rank(∂C_passive/∂s)`` (motors as passive
    joints). Idle spins are not counted: the passive rows include their gauge rows
    (:func:`linkopt._engine.constraints.gauge_rows`)."""
    values = np.linalg.svd(np.asarray(_passive_jacobian(mech)), compute_uv=False)
    rank = int(np.sum(values > RANK_TOL * values[0]))
    return mech.state_size - rank


def check_mobility(mech: Mechanism) -> None:
    """Motors and outputs must each number the mobility, and rest must not be
    singular."""
    dof = mobility(mech)
    if mech.num_motors != dof:
        raise MechanismFileError(
            mech.source,
            "[[motors]]",
            f"the mechanism has mobility {dof} at the rest pose but {mech.num_motors} "
            f"motor(s); they must be equal{_idle_note(mech)}",
        )
    if mech.num_outputs != dof:
        raise MechanismFileError(
            mech.source,
            "[[outputs]]",
            f"the mechanism has mobility {dof} at the rest pose but {mech.num_outputs} "
            "output(s); they must be equal",
        )
    sigma_fk, sigma_bk = np.asarray(_rest_sigmas(mech))
    if not sigma_fk >= SINGULAR_TOL:  # NaN too
        raise MechanismFileError(
            mech.source,
            "[[motors]]",
            f"the rest pose is a forward singularity (σ_min = {sigma_fk:.2e}): the "
            "motors do not determine the mechanism there",
        )
    if not sigma_bk >= SINGULAR_TOL:  # NaN too
        raise MechanismFileError(
            mech.source,
            "[[outputs]]",
            f"the rest pose is a backward singularity (σ_min = {sigma_bk:.2e}): the "
            "outputs do not determine the mechanism there",
        )


def _idle_note(mech: Mechanism) -> str:
    """What the mobility message says about idle spins: those already fixed."""
    count = mech.idle_bodies.size
    if not count:
        return ""
    return (
        f" ({count} idle spin(s) of rods between two ball joints are already fixed "
        "by gauge rows and not counted)"
    )
