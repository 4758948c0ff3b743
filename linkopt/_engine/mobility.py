"""Mobility at the rest pose and the load-time checks that depend on it."""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._errors import InputError, MechanismFileError
from . import banded, banded_sigma, programs, singularity
from .constraints import (
    homogenised_motor_values,
    output_residual,
    passive_residual,
)
from .geometry import geometry, rest_state
from .jacobian import state_jacobian
from .lifting import padded_design
from .model import Mechanism
from .singularity import sigmas_of, stacked_jacobians

RANK_TOL = 1e-9  # relative to the largest singular value
SINGULAR_TOL = (
    1e-7  # absolute σ_min (homogenised) below which the rest pose is singular
)


@dataclass(frozen=True)
class RestJacobians:
    """What the load-time checks and α₋ read at the rest pose, homogenised. The FK
    and BK Jacobians have one row per motor and per output on top of the passive
    rows, so a file whose motor and output counts differ (refused by
    :func:`check_mobility`) has ``sigmas`` and ``stacked`` None. On the band
    (:func:`linkopt._engine.banded.serves`) no dense Jacobian is formed: ``passive``
    and ``stacked`` are None and ``rates`` holds what the input-output Jacobian
    needs (:func:`_banded_rest_program`); on the dense path ``rates`` is None."""

    passive: Float[Array, "P S"] | None  # ∂C_passive/∂s (motors as passive joints)
    sigmas: Float[Array, 2] | None  # (σ_min^FK, σ_min^BK)
    stacked: Float[Array, "2 R S"] | None  # [∂C_FK/∂s, ∂C_BK/∂s]
    rates: Float[Array, "K M"] | None = None  # homogenised ∂b/∂a, on the band


def _rest_program(mech: Mechanism) -> tuple:
    """The passive rows are the top rows of the closed-form FK Jacobian (passive rows,
    then one row per motor: :mod:`.jacobian`), which σ_min needs anyway; they equal
    ``jax.jacfwd`` of :func:`~.constraints.passive_residual` up to rounding."""
    geom = geometry(mech)
    state = rest_state(mech)
    if mech.num_motors != mech.num_outputs:
        fk = state_jacobian(mech, geom, "fk", state)
        return fk[: fk.shape[0] - mech.num_motors], None, None
    stacked = stacked_jacobians(mech, geom, state)
    passive = stacked[0, : stacked.shape[1] - mech.num_motors]
    return passive, sigmas_of(stacked), stacked


def _banded_rest_program(mech: Mechanism) -> tuple:
    """``(σ_min^FK, σ_min^BK)`` on the band (:mod:`.banded_sigma`) and the
    homogenised ``∂b/∂a``: the state velocity of a unit motor velocity is the least
    squares solution of ``∂C_FK/∂s ṡ = (0, e_i)`` (``(JᵀJ)⁻¹Jᵀ``, one banded factor),
    the outputs' velocity the output rows of ``∂C_BK/∂s ṡ`` (a forward-mode product
    through those rows alone);
    what :func:`linkopt._design.conditioning.input_output_jacobian` gives from the
    dense Jacobians."""
    geom = geometry(mech)
    state = rest_state(mech)
    motors, outputs = jnp.zeros(mech.num_motors), jnp.zeros(mech.num_outputs)
    unit = jnp.eye(mech.num_motors)
    projected = banded.motor_rows_transposed(mech, geom, motors, state, unit)
    velocity = banded.normal_solve(mech, "fk", geom, state, projected)

    def output_rates(v):
        return jax.jvp(
            lambda s: output_residual(mech, geom, outputs, s), (state,), (v,)
        )[1]

    rates = jax.vmap(output_rates, in_axes=1, out_axes=1)(velocity)
    sigmas = banded_sigma.sigma_min_pair(mech, geom, state)
    return sigmas, rates


def rest_jacobians(mech: Mechanism) -> RestJacobians:
    """:class:`RestJacobians` of the file's initial design: one program for every
    check that loading runs and for α₋ (:mod:`.programs`: each new structure compiles
    it once, where three separate programs compiled the shared Jacobian rows three
    times). On the band: σ_min and ``∂b/∂a`` only (the mobility is
    :func:`banded_mobility`'s)."""
    if not banded.serves(mech):
        return RestJacobians(*programs.call("rest_jacobians", mech, _rest_program))
    if mech.num_motors != mech.num_outputs:
        return RestJacobians(None, None, None)
    sigmas, rates = programs.call("banded_rest", mech, _banded_rest_program)
    return RestJacobians(None, sigmas, None, rates)


def mobility(mech: Mechanism) -> int:
    """Degrees of freedom at rest: ``|s| - rank(∂C_passive/∂s)`` (motors as passive
    joints). Idle spins are not counted: the passive rows include their gauge rows
    (:func:`linkopt._engine.constraints.gauge_rows`). On the band
    (:func:`linkopt._engine.banded.serves`): :func:`banded_mobility`, linear in the
    bodies, where the SVD of the dense passive Jacobian is cubic."""
    if banded.serves(mech):
        return banded_mobility(mech)
    values = np.linalg.svd(np.asarray(rest_jacobians(mech).passive), compute_uv=False)
    rank = int(np.sum(values > RANK_TOL * values[0]))
    return mech.state_size - rank


#: Inverse-iteration sweeps of the banded rank test: per sweep, the block's error
#: shrinks by ``(λ_k + shift)/(λ_k+1 + shift)`` (the eigenvalues of ``JᵀJ``).
RANK_SWEEPS = 12
#: The rank test factors ``JᵀJ + RANK_SHIFT·λ_max·I``: far above the factor's
#: rounding (about ``7(w + 1)·ε·λ_max``), and, unlike σ_min's ``SHIFT·trace``, not
#: growing with the bodies: a long truss has many singular values of ``J`` near
#: ``1e-5`` (a 1000-body ladder's σ_min at rest: 1.9e-5), and a shift above their
#: squares would blur the null space into them (a 3000-body ladder then counted no
#: null space at all).
RANK_SHIFT = 1e-13


def _null_block(mech: Mechanism, geom, state, start):
    """``(x, J x, λ_max)``: an orthonormal block ``x`` ``(S, k)`` holding the passive
    Jacobian's ``k`` smallest right singular vectors at ``state`` (block inverse
    iteration on the band from ``start``), its image ``J x`` and ``JᵀJ``'s largest
    eigenvalue."""
    band, where = banded.passive_normal(mech, geom, state)
    top = banded_sigma.largest_eigenvalue(band)
    block = banded_sigma.smallest_subspace(band, start, RANK_SWEEPS, RANK_SHIFT * top)
    vectors = jax.vmap(lambda x: banded.unpermute(where, x), in_axes=2, out_axes=1)(
        block
    )

    def image(v):
        return jax.jvp(lambda s: passive_residual(mech, geom, s), (state,), (v,))[1]

    images = jax.vmap(image, in_axes=1, out_axes=1)(vectors)
    return vectors, images, top


def _passive_null_program(mech: Mechanism, start):
    """``(J x, λ_max)`` of :func:`_null_block` at the file's rest pose."""
    _, images, top = _null_block(mech, geometry(mech), rest_state(mech), start)
    return images, top


def _null_count(images: np.ndarray, top) -> int:
    """How many singular values of ``J x`` are at most ``RANK_TOL·σ_max``
    (``σ_max² = λ_max``)."""
    values = np.linalg.svd(images, compute_uv=False)
    return int(np.sum(values <= RANK_TOL * np.sqrt(float(top))))


def _first_block(mech: Mechanism) -> int:
    """Columns of the first block of the banded rank test: the motors' null space
    and room to spare."""
    return min(mech.state_size, max(singularity.BLOCK, 2 * mech.num_motors + 2))


def banded_mobility(mech: Mechanism) -> int:
    """:func:`mobility` from the band: the singular values of ``J x`` (``x`` the
    block of :func:`_passive_null_program`, ``k`` columns) are ``J``'s ``k``
    smallest; those at most ``RANK_TOL·σ_max`` (``σ_max² = λ_max(JᵀJ)``) count the
    null space, as the dense SVD's do. A null space as large as the block is tried
    again with twice the block, so a mobility of any size is counted."""
    k = _first_block(mech)
    while True:
        start = banded_sigma.start_block(mech.num_bodies, k)
        images, top = programs.call(
            "passive_null", mech, _passive_null_program, jnp.asarray(start)
        )
        null = _null_count(np.asarray(images), top)
        if null < k or k == mech.state_size:
            return null
        k = min(mech.state_size, 2 * k)


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
    sigma_fk, sigma_bk = np.asarray(rest_jacobians(mech).sigmas)
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


# --- the mobility of other designs ----------------------------------------------------

#: A motor whose rate is below this on every motion the rest pose allows (homogenised,
#: per unit state velocity) no longer moves.
LOCKED_TOL = 1e-8


@dataclass(frozen=True)
class MobilityChange:
    """A design whose rest pose has another mobility than its motors number:
    ``mobility`` found, ``locked`` the motors that cannot move at all there."""

    design: np.ndarray
    mobility: int
    locked: tuple[str, ...]

    def words(self, mech: Mechanism) -> str:
        """One line naming the design, the mobility and the motors."""
        named = ", ".join(
            f"{n} = {v:.6g}" for n, v in zip(mech.design.names, self.design)
        )
        motors = mech.num_motors
        if self.mobility > motors:
            what = (
                f"more motions than its {motors} motor(s) fix: the rest pose is "
                "singular for this design"
            )
        elif self.locked:
            what = f"motor(s) {', '.join(self.locked)} no longer move"
        else:
            what = (
                f"motors {', '.join(mech.motor_names)} no longer move independently "
                f"(only {self.mobility} of them can be set)"
            )
        return (
            f"the design ({named}) has mobility {self.mobility} at the rest pose, the "
            f"file's {motors}: {what}"
        )


def _design_rest_program(mech: Mechanism, designs):
    """Per design: the passive Jacobian and the motors' Jacobian at the rest pose."""
    state = rest_state(mech)

    def one(design):
        geom = geometry(mech, design)
        passive = jax.jacfwd(lambda s: passive_residual(mech, geom, s))(state)
        motors = jax.jacfwd(lambda s: homogenised_motor_values(mech, geom, s))(state)
        return passive, motors

    return jax.vmap(one)(designs)


def mobility_changes(mech: Mechanism, designs) -> list[MobilityChange | None]:
    """For each design ``(N, n_p)`` (file units): None where its rest pose has the
    mobility the motors number (the file's, checked on loading), else what changed
    (a design that turns a spherical loop into a general spatial one that locks)."""
    designs = np.atleast_2d(np.asarray(designs, dtype=np.float64))
    if banded.serves(mech):
        return _banded_changes(mech, designs)
    passive, motors = _rest_jacobians_of(mech, padded_design(mech, designs))
    values = np.linalg.svd(passive, compute_uv=False)  # (N, min(P, S)), batched
    ranks = np.sum(values > RANK_TOL * values[:, :1], axis=1)
    return [
        None
        if mech.state_size - rank == mech.num_motors
        else _change(mech, d, p, np.asarray(m))
        for d, p, m, rank in zip(designs, passive, motors, ranks)
    ]


#: Designs per call of the mobility program: a swarm, ``verify`` and the export all
#: run the one program compiled for this batch (the last batch is padded by repeating
#: its last design), where each batch size compiled a program of its own.
MOBILITY_BATCH = 8


def _rest_jacobians_of(mech: Mechanism, padded: np.ndarray) -> tuple:
    """The passive and motor Jacobians at rest of each padded design ``(N, P)``, as
    numpy arrays, in batches of :data:`MOBILITY_BATCH`."""
    return _in_batches(mech, padded, "design_mobility", _design_rest_program)


def _in_batches(mech: Mechanism, padded: np.ndarray, name: str, fn, *args) -> tuple:
    """``programs.call(name, mech, fn, batch, *args)`` over the padded designs ``(N,
    P)`` in batches of :data:`MOBILITY_BATCH` (the last padded by repeating its last
    design), each output as one numpy array over the ``N`` designs."""
    count = len(padded)
    total = -(-count // MOBILITY_BATCH) * MOBILITY_BATCH
    padded = np.concatenate([padded, np.repeat(padded[-1:], total - count, axis=0)])
    parts = [
        programs.call(name, mech, fn, padded[start : start + MOBILITY_BATCH], *args)
        for start in range(0, total, MOBILITY_BATCH)
    ]
    return tuple(
        np.concatenate([np.asarray(p[k]) for p in parts])[:count]
        for k in range(len(parts[0]))
    )


def _design_null_program(mech: Mechanism, designs, start):
    """Per design: :func:`_null_block` at the rest pose and the motors' rates along
    the block ``(M, k)`` (forward-mode products, never a dense Jacobian)."""
    state = rest_state(mech)

    def one(design):
        geom = geometry(mech, design)
        vectors, images, top = _null_block(mech, geom, state, start)

        def rate(v):
            return jax.jvp(
                lambda s: homogenised_motor_values(mech, geom, s), (state,), (v,)
            )[1]

        return images, top, jax.vmap(rate, in_axes=1, out_axes=1)(vectors)

    return jax.vmap(one)(designs)


def _banded_changes(mech: Mechanism, designs) -> list[MobilityChange | None]:
    """:func:`mobility_changes` on the band: per design the rank test of
    :func:`banded_mobility` (the block widened while a design's null space fills
    it), the locked motors from the null directions found in the block."""
    padded = padded_design(mech, designs)
    k = _first_block(mech)
    while True:
        start = jnp.asarray(banded_sigma.start_block(mech.num_bodies, k))
        parts = _in_batches(mech, padded, "design_null", _design_null_program, start)
        images, tops, rates = parts
        counts = [_null_count(i, t) for i, t in zip(images, tops)]
        if max(counts) < k or k == mech.state_size:
            break
        k = min(mech.state_size, 2 * k)
    return [
        None if count == mech.num_motors else _banded_change(mech, d, i, r, count)
        for d, i, r, count in zip(designs, images, rates, counts)
    ]


def _banded_change(mech, design, images, rates, count: int) -> MobilityChange:
    """:func:`_change` from the block: the null directions are ``x w`` for the right
    singular vectors ``w`` of ``J x`` of its ``count`` smallest values, the motors'
    rates along them ``rates w``."""
    _, _, wt = np.linalg.svd(images)
    null = wt[wt.shape[0] - count :].T  # (k, count)
    locked = tuple(
        name
        for name, row in zip(mech.motor_names, rates @ null)
        if np.linalg.norm(row) <= LOCKED_TOL
    )
    return MobilityChange(np.asarray(design), count, locked)


def _change(mech: Mechanism, design, passive, motors) -> MobilityChange:
    """What changed at ``design``: the mobility, and the motors whose rate is zero on
    every motion the rest pose allows (the null space of the passive rows)."""
    _, values, vt = np.linalg.svd(passive)
    rank = int(np.sum(values > RANK_TOL * values[0]))
    rates = motors @ vt[rank:].T  # each motor's rate on each allowed motion
    locked = tuple(
        name
        for name, row in zip(mech.motor_names, rates)
        if np.linalg.norm(row) <= LOCKED_TOL
    )
    return MobilityChange(np.asarray(design), mech.state_size - rank, locked)


def check_design_mobility(mech: Mechanism, design, where: str) -> None:
    """:class:`~linkopt.InputError` naming ``where`` when ``design`` changes the
    mobility at rest (:func:`mobility_changes`)."""
    (change,) = mobility_changes(mech, design)
    if change is not None:
        raise InputError(f"{where}: {change.words(mech)}")
