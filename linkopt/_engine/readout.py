"""Quantities read off a homogenised state, returned in file units."""

from __future__ import annotations

from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .._config import jit, traced
from . import constraints, programs
from .blocks import in_blocks
from .geometry import design_array, design_vector, geometry
from .model import Mechanism


@partial(jit, static_argnums=1)
def _read(mech: Mechanism, what: str, state, design):
    geom = geometry(mech, design_vector(mech, design))
    fn = {
        "motors": lambda s: (
            constraints.homogenised_motor_values(mech, geom, s) * mech.motor_scale
        ),
        "outputs": lambda s: (
            constraints.homogenised_output_values(mech, geom, s) * mech.output_scale
        ),
        "joints": lambda s: (
            constraints.homogenised_joint_positions(mech, geom, s) * mech.length_scale
        ),
        "points": lambda s: (
            constraints.homogenised_point_positions(mech, geom, s) * mech.length_scale
        ),
        "reported": lambda s: (
            constraints.reported_values(mech, geom, s)
            * mech.reported_table.scale(mech.length_scale)
        ),
    }[what]
    state = jnp.asarray(state, dtype=jnp.float64)
    return fn(state) if state.ndim == 1 else jax.vmap(fn)(state)


def _blocked_read(mech: Mechanism, what: str, state, design):
    """:func:`_read`, a concrete batch of states in fixed blocks
    (:mod:`linkopt._engine.blocks`: one program for every batch size)."""
    if traced(mech, state, design):
        return _read(mech, what, state, design)
    design = design_array(mech, design)  # None and arrays: one program

    def read(s):  # the trace kept on disk (.programs)
        return programs.call(
            f"read_{what}", mech, lambda m, *a: _read(m, what, *a), s, design
        )

    state = np.asarray(state, dtype=np.float64)
    return read(state) if state.ndim != 2 else in_blocks(read, (state,), one=read)


def motor_values(mech: Mechanism, state, *, design=None) -> Float[Array, "... M"]:
    """Motor values of a state (rad, or file units for linear motors)."""
    return _blocked_read(mech, "motors", state, design)


def output_values(mech: Mechanism, state, *, design=None) -> Float[Array, "... K"]:
    """End-effector variables ``b(s)`` (file units, rad for angles)."""
    return _blocked_read(mech, "outputs", state, design)


def joint_positions(mech: Mechanism, state, *, design=None) -> Float[Array, "... J 3"]:
    """World position of every joint anchor (file units), in ``mech.joint_names``
    order."""
    return _blocked_read(mech, "joints", state, design)


def point_positions(mech: Mechanism, state, *, design=None) -> Float[Array, "... P 3"]:
    """World position of every named point (file units), in ``mech.point_names``
    order; :func:`named_points` gives them by name."""
    return _blocked_read(mech, "points", state, design)


def reported_values(mech: Mechanism, state, *, design=None) -> Float[Array, "... E"]:
    """Values of the reported outputs (``reported = true``; file units, rad for
    angles) in ``mech.reported_table.names`` order; shape ``(..., 0)`` when the file
    has none. BK and the design evaluation never use them."""
    if not mech.reported_table.size:
        shape = np.shape(state)[:-1] + (0,)
        return jnp.zeros(shape)
    return _blocked_read(mech, "reported", state, design)


def named_points(mech: Mechanism, state, *, design=None) -> dict[str, np.ndarray]:
    """``{name: position}`` of every named point (file units): the rows of
    :func:`point_positions` under their names, shape ``(3,)`` each (``(N, 3)`` for a
    stack of states)."""
    positions = np.asarray(point_positions(mech, state, design=design))
    return {name: positions[..., k, :] for k, name in enumerate(mech.point_names)}
