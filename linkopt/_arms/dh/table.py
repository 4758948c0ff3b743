"""Denavit–Hartenberg serial arms: closed-form kinematics and the equivalent Mechanism.

Convention (paper 004, ref. [6], Spong & Vidyasagar; the *standard, distal* one): link
``i`` carries frame ``i`` and

    A_i = Rot_z(θ_i) Trans_z(d_i) Trans_x(a_i) Rot_x(α_i),    T_k = A_1 A_2 ... A_k,

with frame 0 the world frame. Joint ``i`` moves link ``i`` relative to link ``i-1``
about (R) or along (P) the axis ``z_{i-1}`` through the origin of frame ``i-1``. Its
joint variable is ``θ_i`` for a revolute and ``d_i`` for a prismatic joint; the other
of the two is a constant. The end effector is the origin of frame ``N``.

A table is stored as three arrays (a pytree, so it can be optimised and vmapped): ``a``,
``alpha`` and ``offset``, where ``offset_i`` is the constant one of ``(d_i, θ_i)``:
``d_i`` for an R joint and ``θ_i`` for a P joint. The joint-type string (``"RRP"``) is
static.

The equivalent :class:`~linkopt.Mechanism` (:func:`mechanism_definition`, a serial
chain of :mod:`linkopt._arms.chain`) has one body per link (``base`` = link 0 is the
ground), one revolute/prismatic joint per DH joint with its axis ``z_{i-1}`` at a
chosen rest configuration ``q_rest``, a motor on every joint and a named point ``tip``
at the origin of frame ``N``. Mechanism bodies are at the identity orientation at rest
and motors are measured from rest, so a motor value is ``q - q_rest`` (rad for R, file
units for P). Each body's frame origin is written explicitly as the origin of its DH
frame at rest, which makes the engine state of any configuration a closed-form function
of ``q`` (:func:`engine_state`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..._config import jit
from ..._engine import rotations as rot
from ..._errors import InputError
from ..chain import chain_definition, chain_state, coordinate_output, joint_output, span

JOINT_LETTERS = "RP"
_Z = np.array([0.0, 0.0, 1.0])
_X = np.array([1.0, 0.0, 0.0])
_COORDS = "xyz"


@jax.tree_util.register_dataclass
@dataclass(frozen=True)
class DHTable:
    """Constant DH parameters of an N-joint arm; every field has shape ``(N,)``.

    ``offset`` is ``d_i`` for a revolute joint and ``θ_i`` (rad) for a prismatic one.
    """

    a: Float[Array, " N"]
    alpha: Float[Array, " N"]
    offset: Float[Array, " N"]


def check_joint_types(types: str, where: str = "joint types") -> str:
    """``types`` upper-cased if it is a non-empty string of 'R'/'P', else
    :class:`InputError`."""
    text = str(types).strip().upper()
    if not text or any(c not in JOINT_LETTERS for c in text):
        raise InputError(
            f"{where}: expected a non-empty string of 'R' (revolute) and 'P' "
            f"(prismatic), got {types!r}"
        )
    return text


def table_from_arrays(types: str, a, alpha, offset) -> DHTable:
    """A :class:`DHTable` from sequences, checking that every length equals
    ``len(types)``."""
    arrays = [np.asarray(v, dtype=float).reshape(-1) for v in (a, alpha, offset)]
    for name, v in zip(("a", "alpha", "offset"), arrays):
        if v.shape != (len(types),) or not np.all(np.isfinite(v)):
            raise InputError(
                f"DH table: {name}: expected {len(types)} finite numbers (one per "
                f"joint of {types!r}), got {v.tolist()}"
            )
    return DHTable(*(jnp.asarray(v) for v in arrays))


def joint_parameters(
    types: str, table: DHTable, q: Float[Array, " N"]
) -> tuple[Float[Array, " N"], Float[Array, " N"]]:
    """``(θ, d)`` per joint with the joint variables ``q`` substituted (R: θ = q, P: d =
    q)."""
    revolute = np.array([c == "R" for c in types])
    theta = jnp.where(revolute, q, table.offset)
    d = jnp.where(revolute, table.offset, q)
    return theta, d


def link_transform(theta, d, a, alpha) -> Float[Array, "4 4"]:
    """``A = Rot_z(θ) Trans_z(d) Trans_x(a) Rot_x(α)`` (distal DH), a 4×4 homogeneous
    matrix."""
    ct, st, ca, sa = jnp.cos(theta), jnp.sin(theta), jnp.cos(alpha), jnp.sin(alpha)
    zero, one = jnp.zeros_like(ct), jnp.ones_like(ct)
    return jnp.stack(
        [
            jnp.stack([ct, -st * ca, st * sa, a * ct]),
            jnp.stack([st, ct * ca, -ct * sa, a * st]),
            jnp.stack([zero, sa, ca, d]),
            jnp.stack([zero, zero, zero, one]),
        ]
    )


def frames(
    types: str, table: DHTable, q: Float[Array, " N"]
) -> Float[Array, "N+1 4 4"]:
    """``T_0 = I, T_1, ..., T_N``: the world pose of every DH frame at joint values
    ``q``."""
    theta, d = joint_parameters(types, table, q)
    poses = [jnp.eye(4)]
    for i in range(len(types)):
        poses.append(
            poses[-1] @ link_transform(theta[i], d[i], table.a[i], table.alpha[i])
        )
    return jnp.stack(poses)


def tip_position(types: str, table: DHTable, q: Float[Array, " N"]) -> Float[Array, 3]:
    """Origin of frame N (the end effector) in the world frame."""
    return frames(types, table, q)[-1, :3, 3]


def tip_jacobian(
    types: str, table: DHTable, q: Float[Array, " N"]
) -> Float[Array, "3 N"]:
    """Linear velocity Jacobian ``∂p/∂q`` of the end effector (rad for R, lengths for
    P)."""
    return jax.jacfwd(lambda v: tip_position(types, table, v))(q)


@partial(jit, static_argnums=0)
def frames_and_jacobian(
    types: str, table: DHTable, q: Float[Array, " N"]
) -> tuple[Float[Array, "N+1 4 4"], Float[Array, "3 N"]]:
    """:func:`frames` and :func:`tip_jacobian` at ``q`` in one compiled program (run
    op by op on concrete arrays they compiled some ninety small ones, in every
    process: too small for the disk cache)."""
    return frames(types, table, q), tip_jacobian(types, table, q)


def size(types: str, table: DHTable) -> Float[Array, ""]:
    """Σ|a_j| + Σ|d_j| over the constant offsets only (paper eq. 9: ``d_j ∉ q``)."""
    revolute = np.array([c == "R" for c in types])
    return jnp.sum(jnp.abs(table.a)) + jnp.sum(
        jnp.where(revolute, jnp.abs(table.offset), 0.0)
    )


def _orientations(types: str, table: DHTable, q) -> Float[Array, "N+1 4"]:
    """Quaternion (wxyz) of every DH frame: products of ``Rot_z(θ_i) Rot_x(α_i)``."""
    theta, _ = joint_parameters(types, table, q)
    quats = [jnp.array([1.0, 0.0, 0.0, 0.0])]
    for i in range(len(types)):
        step = rot.multiply(
            rot.from_axis_angle(jnp.asarray(_Z), theta[i]),
            rot.from_axis_angle(jnp.asarray(_X), table.alpha[i]),
        )
        quats.append(rot.multiply(quats[-1], step))
    return jnp.stack(quats)


def engine_state(
    types: str,
    table: DHTable,
    q: Float[Array, " N"],
    q_rest: Float[Array, " N"],
    length_scale: float,
) -> Float[Array, " S"]:
    """The homogenised state of the equivalent Mechanism at joint values ``q``.

    Body ``k`` (link ``k``) carries DH frame ``k`` and its origin is that frame's origin
    at rest, so it sits at the origin of frame ``k``; its orientation is the rotation
    from its rest frame, ``R_k(q) R_k(q_rest)ᵀ``
    (:func:`linkopt._arms.chain.chain_state`).
    """
    return chain_state(
        _orientations(types, table, q),
        frames(types, table, q)[:, :3, 3],
        _orientations(types, table, q_rest),
        length_scale,
    )


@partial(jit, static_argnums=(0, 4))
def engine_states(
    types: str,
    table: DHTable,
    q: Float[Array, "m N"],
    q_rest: Float[Array, " N"],
    length_scale: float,
) -> Float[Array, "m S"]:
    """:func:`engine_state` of every row of ``q``, vmapped and jitted."""
    return jax.vmap(lambda v: engine_state(types, table, v, q_rest, length_scale))(q)


def _output_coordinates(jac: np.ndarray, count: int) -> tuple[int, ...]:
    """For an arm with fewer than 3 joints: the ``count`` tip coordinates whose rows of
    the rest Jacobian are best conditioned (largest ``|det|``), so the outputs are
    independent."""
    import itertools

    best = max(
        itertools.combinations(range(3), count),
        key=lambda c: abs(np.linalg.det(jac[list(c)])),
    )
    return tuple(best)


def _coordinate_outputs(types: str, jac, tip, bounds) -> list[dict]:
    """The tip coordinates that are outputs (all three for N ≥ 3), each ranging over
    ``bounds`` (default a unit box around the rest tip) and the rest tip."""
    n = len(types)
    coords = (0, 1, 2) if n >= 3 else _output_coordinates(jac, n)
    lo, hi = (
        (tip - 1.0, tip + 1.0)
        if bounds is None
        else (np.asarray(bounds[0], float), np.asarray(bounds[1], float))
    )
    return [
        coordinate_output(
            _COORDS[c],
            "tip",
            _COORDS[c],
            float(min(lo[c], tip[c])),
            float(max(hi[c], tip[c]) + 1e-9),
        )
        for c in coords
    ]


def _outputs(types: str, jac: np.ndarray, tip: np.ndarray, bounds) -> list[dict]:
    """Tip coordinates as outputs (all three for N ≥ 3), plus, for N > 3, the angles of
    the last N - 3 revolute joints, so that #outputs equals the mobility N as the loader
    requires."""
    n = len(types)
    extra = [i for i, c in enumerate(types) if c == "R"][::-1][: max(0, n - 3)]
    if len(extra) < n - 3:
        raise InputError(
            f"joint types {types!r}: an equivalent mechanism file of a {n}-joint arm "
            f"needs {n - 3} revolute joints whose angles complete the outputs; it has "
            f"{len(extra)}"
        )
    return _coordinate_outputs(types, jac, tip, bounds) + [
        joint_output(f"q{i + 1}", f"joint{i + 1}", -np.pi, np.pi) for i in sorted(extra)
    ]


def mechanism_definition(
    types: str,
    table: DHTable,
    q_rest,
    *,
    name: str = "DH arm",
    bounds=None,
    units: str = "",
) -> dict:
    """The parsed-TOML definition of the arm with its rest pose at joint values
    ``q_rest``.

    ``bounds`` = ``(lower (3,), upper (3,))`` of the tip outputs' ranges (e.g. the task
    points' bounding box); default a unit box around the rest tip. ``q_rest`` should be
    a non-singular configuration (the loader rejects a singular rest pose).
    """
    q_rest = jnp.asarray(q_rest, dtype=float)
    poses, jac = (np.asarray(a) for a in frames_and_jacobian(types, table, q_rest))
    origins, z_axes = poses[:, :3, 3], poses[:, :3, 2]
    n = len(types)
    return chain_definition(
        name,
        ["base"] + [f"link{k}" for k in range(1, n + 1)],
        [f"joint{k}" for k in range(1, n + 1)],
        [f"q{k}" for k in range(1, n + 1)],
        origins[:-1],
        [z / np.linalg.norm(z) for z in z_axes[:-1]],
        points=[("tip", n, origins[-1])],
        outputs=_outputs(types, jac, origins[-1], bounds),
        types=types,
        origins=origins,
        units=units,
        reference_length=span(origins),
    )


def to_mechanism(
    types: str,
    table: DHTable,
    q_rest,
    *,
    name: str = "DH arm",
    bounds=None,
    source: str = "<DH table>",
):
    """``(Mechanism, TOML text)`` of the arm (see :func:`mechanism_definition`), loaded
    by :func:`linkopt.loads`, so it passes every check a mechanism file does."""
    from ..._files.loader import loads
    from ..._files.writer import dumps

    text = dumps(mechanism_definition(types, table, q_rest, name=name, bounds=bounds))
    return loads(text, source), text


def motor_values(
    q: Float[Array, "... N"], q_rest: Float[Array, " N"]
) -> Float[Array, "... N"]:
    """Motor values of the equivalent Mechanism: joint values measured from the rest
    pose."""
    return jnp.asarray(q) - jnp.asarray(q_rest)
