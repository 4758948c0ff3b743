"""Design vector -> homogenised rest geometry (anchors, axes, points) and the rest
state."""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _config  # noqa: F401  (float64 on before any array)
from .following import rest_points
from .lifting import padded_design
from .model import Mechanism
from .rotations import axis_angle_matrix, unit
from .structure import flatten as _registered  # noqa: F401  (Mechanism is a pytree)


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class Geometry:
    """Rest geometry of one design, homogenised (lengths divided by ``length_scale``).

    All world-frame, rest pose; body-local quantities follow by subtracting the static
    body origins since every body has the identity orientation at rest.
    """

    anchors: Float[Array, "J 3"]
    axes: Float[Array, "J 3"]  # unit primary axis n
    helpers: Float[Array, "J 3"]  # unit u ⟂ n; (u, n × u, n) is right-handed
    axes2: Float[Array, "J 3"]  # unit second axis of universal joints, ⟂ n
    points: Float[Array, "P 3"]
    origins: Float[Array, "B 3"]


def _perpendicular(
    v: Float[Array, "J 3"], n: Float[Array, "J 3"]
) -> Float[Array, "J 3"]:
    return unit(jnp, v - jnp.sum(v * n, axis=-1, keepdims=True) * n)


def design_vector(mech: Mechanism, design=None) -> Float[Array, " n_p"]:
    """The design vector as a float64 array; ``None`` means the file's initial
    design."""
    if design is None:
        return jnp.asarray(mech.design.p0, dtype=jnp.float64)
    return jnp.asarray(design, dtype=jnp.float64)


def design_array(mech: Mechanism, design=None) -> np.ndarray:
    """A concrete ``design`` (None: the file's) as the argument of a program of
    :mod:`.programs`: numpy, padded to the design class
    (:func:`.lifting.padded_design`), so None and arrays are one argument structure
    and every file of one class shares the program."""
    return padded_design(mech, mech.design.p0 if design is None else design)


def moved_joints(
    mech: Mechanism, design=None
) -> tuple[Float[Array, "J 3"], Float[Array, "J 3"]]:
    """Joint anchors (file units) and primary axes (not normalised: unit at the
    file's design, moved by the design's linear map) of the design ``p``, traceable
    in ``p``."""
    p = design_vector(mech, design)
    joints = mech.anchors.shape[0]
    flat0 = jnp.concatenate([jnp.ravel(mech.anchors), jnp.ravel(mech.axes)])
    change = p - mech.design.p0
    flat = flat0 + jnp.asarray(mech.design.matrix) @ change
    anchors = flat[: 3 * joints].reshape(joints, 3)
    axes = flat[3 * joints :].reshape(joints, 3)
    turns = mech.design.turns
    if turns is None:
        return anchors, axes
    for t in range(turns.select.shape[0]):  # downstream first (Turns)
        rotation = axis_angle_matrix(
            turns.normals[t], jnp.asarray(turns.select[t]) @ change
        )
        center = jnp.asarray(turns.centers[t])
        on = jnp.asarray(turns.joints[t])[:, None] > 0.5
        anchors = jnp.where(on, center + (anchors - center) @ rotation.T, anchors)
        axes = jnp.where(on, axes @ rotation.T, axes)
    return anchors, axes


def geometry(mech: Mechanism, design=None) -> Geometry:
    """Homogenised rest geometry of the design ``p`` (file units), traceable in
    ``p``."""
    anchors, raw_axes = moved_joints(mech, design)
    has_axis = mech.axis_present[:, None]
    axes = jnp.where(has_axis, unit(jnp, raw_axes), 0.0)
    helpers = _perpendicular(jnp.asarray(np.eye(3)[mech.helper_index]), axes)
    axes2 = _perpendicular(jnp.asarray(mech.axes2), axes)
    change = design_vector(mech, design) - mech.design.p0
    points = rest_points(mech, anchors, change)
    scale = mech.length_scale
    return Geometry(
        anchors=anchors / scale,
        axes=axes,
        helpers=helpers,
        axes2=axes2,
        points=points / scale,
        origins=jnp.asarray(mech.body_origins / scale),
    )


def rest_state(mech: Mechanism) -> Float[Array, " S"]:
    """Homogenised rest state: body origins and identity quaternions, shape
    ``(7B,)``; traceable in the mechanism's numbers (:mod:`.lifting`)."""
    xp = np if isinstance(mech.body_origins, np.ndarray) else jnp
    origins = mech.body_origins / mech.length_scale
    quats = xp.tile(xp.array([1.0, 0.0, 0.0, 0.0]), (mech.num_bodies, 1))
    return jnp.asarray(xp.concatenate([origins, quats], axis=1).ravel())
