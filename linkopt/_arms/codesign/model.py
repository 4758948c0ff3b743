"""Serial arms built from modules, compiled to an ordinary :class:`~linkopt.Mechanism`.

An arm (paper Sec. III-A) is a sequence of modules; each module is a rigid transform
whose continuous parameters are either fixed numbers or design variables ``d``:

* ``base``   ``Trans(x, y, z) · Rot_z(yaw) Rot_y(pitch) Rot_x(roll)``; its z axis is the
  first joint's axis. Also used as the abstract ``segment`` of joint elimination
  (Sec. V).
* ``joint``  a rotary actuator: ``Rot_z(θ)``, one motor.
* ``link``   ``Trans_z(offset) · Trans_x(length) · Rot_x(twist)``, i.e. one
  Denavit–Hartenberg row ``(d, a, α)`` after the preceding joint's ``Rot_z(θ)``.
* ``tool``   ``Trans_x(length) · Rot_y(π/2)``: the end effector, whose frame's z axis
  (the tip axis ``n̂_fk`` of eq. 3) points along the tool.

Every joint module starts a new body; the modules up to the next joint are rigid parts
of that body. The engine model (:func:`make_arm`, a serial chain of
:mod:`linkopt._arms.chain`) has a ground body and one body per joint, one revolute
joint and motor per joint module, and one named point at the end of every module
(``m<k>``, plus ``tip``). Its outputs are the joint angles: an open chain's
loader check needs as many outputs as motors, and tip coordinates would make the
stretched zero pose (the usual rest pose of a DH chain) backward-singular.

Design variables such as a twist are not linear in the anchors, so the engine's linear
design map is not used: :func:`arm_geometry` maps ``d`` to the engine's
:class:`~linkopt._engine.geometry.Geometry` (body origins static, anchors moving inside
the bodies, as everywhere in linkopt), and :func:`arm_state` gives the
maximal-coordinate state of joint angles ``θ`` directly (a serial chain needs no solve),
attached to ``θ`` and ``d`` by the engine's implicit-function tangent, so every
derivative of a state quantity comes from the engine's constraint Jacobian
(:mod:`linkopt._engine.jacobian`).

Joint elimination's reduced arms keep a :class:`Lineage` (where their modules and
design variables sit in the task's arm) and can be written over that root arm as a
traced :class:`Layout`: :func:`chain` masks the dropped modules to the identity and
inserts the free segment, so one compiled program of the root's engine model serves
every reduced arm (:mod:`linkopt._arms.codesign.elimination`).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..._engine import rotations as rot
from ..._engine.constraints import homogenised_point_positions
from ..._engine.geometry import Geometry
from ..._engine.kinematics import implicit_state
from ..._engine.model import Mechanism
from ..._errors import InputError
from ..._files.loader import build
from ..chain import chain_definition, chain_state, joint_output, span

#: Continuous slots of each module kind, in order, and whether each is a length.
SLOTS: dict[str, tuple[str, ...]] = {
    "base": ("x", "y", "z", "roll", "pitch", "yaw"),
    "segment": ("x", "y", "z", "roll", "pitch", "yaw"),
    "joint": (),
    "link": ("length", "twist", "offset"),
    "tool": ("length",),
}
LENGTH_SLOTS = frozenset({"x", "y", "z", "length", "offset"})


@dataclass(frozen=True)
class Module:
    """One module: kind, per-slot ``(design index or -1, fixed value)``, mass (kg)."""

    kind: str
    slots: tuple[tuple[int, float], ...]
    mass: float


@dataclass(frozen=True, eq=False)
class Lineage:
    """Where a reduced arm's parts sit in the arm it was reduced from (joint
    elimination, :mod:`~linkopt._arms.codesign.elimination`): ``root`` the first arm,
    ``modules`` the root index of every module ``(K,)``, ``design`` the root index of
    every design variable ``(m,)``."""

    root: Arm
    modules: np.ndarray  # (K,)
    design: np.ndarray  # (m,)


class Layout(NamedTuple):
    """A reduced arm written over its root's modules, as traced data (so one compiled
    program serves every reduction): ``present`` ``(K,)`` whether each non-joint module
    is kept (a dropped one is the identity; a dropped joint is held at θ = 0 by the
    caller), ``segment`` ``(K,)`` where a free ``segment`` transform follows (at most
    one ``True``), its six parameters the last six entries of ``d``."""

    present: Array  # (K,) bool
    segment: Array  # (K,) bool


@dataclass(frozen=True, eq=False)
class Arm:
    """A serial arm: modules, design space ``d`` (``m`` entries) and actuator data.

    Hashed by identity (a static ``jit`` argument). ``mechanism`` is the engine model
    built at ``d0``; ``torque_limit`` is τ_max of eq. 7 (N·m); ``radius`` the modules'
    collision radius (length units of the task).
    """

    name: str
    modules: tuple[Module, ...]
    design_names: tuple[str, ...]
    d0: np.ndarray  # (m,)
    lower: np.ndarray  # (m,)
    upper: np.ndarray  # (m,)
    is_length: np.ndarray  # (m,) bool
    torque_limit: float
    radius: float
    mechanism: Mechanism
    lineage: Lineage | None = None  # set on the arms joint elimination makes

    @property
    def num_joints(self) -> int:
        return sum(m.kind == "joint" for m in self.modules)

    @property
    def num_design(self) -> int:
        return len(self.design_names)

    @property
    def joint_modules(self) -> np.ndarray:
        """Module index of every joint, shape ``(n,)``."""
        return np.array(
            [k for k, m in enumerate(self.modules) if m.kind == "joint"], dtype=int
        )


Frame = tuple[Float[Array, "4"], Float[Array, "3"]]  # (quaternion wxyz, position)


def compose(a: Frame, b: Frame) -> Frame:
    return rot.multiply(a[0], b[0]), a[1] + rot.rotate(a[0], b[1])


def _rot(axis: int, angle) -> Frame:
    return rot.from_axis_angle(jnp.eye(3)[axis], angle), jnp.zeros(3)


def _trans(vector) -> Frame:
    return jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.asarray(vector, dtype=jnp.float64)


def _slot_values(module: Module, d) -> list:
    return [
        d[i] if i >= 0 else jnp.asarray(v, dtype=jnp.float64) for i, v in module.slots
    ]


def module_transform(module: Module, d, theta=None) -> Frame:
    """The module's transform from its input to its output frame (module docstring)."""
    s = _slot_values(module, d)
    zero = jnp.zeros(())
    if module.kind in ("base", "segment"):
        frame = _trans(jnp.stack(s[:3]))
        for axis, angle in ((2, s[5]), (1, s[4]), (0, s[3])):
            frame = compose(frame, _rot(axis, angle))
        return frame
    if module.kind == "joint":
        return _rot(2, theta)
    if module.kind == "link":
        frame = compose(
            _trans(jnp.stack([zero, zero, s[2]])), _trans(jnp.stack([s[0], zero, zero]))
        )
        return compose(frame, _rot(0, s[1]))
    if module.kind == "tool":
        return compose(_trans(jnp.stack([s[0], zero, zero])), _rot(1, jnp.pi / 2))
    raise InputError(
        f"arm module: unknown kind {module.kind!r}; expected one of {list(SLOTS)}"
    )


def _identity() -> Frame:
    return jnp.array([1.0, 0.0, 0.0, 0.0]), jnp.zeros(3)


def _select(flag, frame: Frame) -> Frame:
    """``frame`` where ``flag``, else the identity."""
    identity = _identity()
    return jnp.where(flag, frame[0], identity[0]), jnp.where(
        flag, frame[1], identity[1]
    )


def chain(
    arm_modules: tuple[Module, ...],
    theta: Float[Array, " n"],
    d: Float[Array, " m"],
    layout: Layout | None = None,
) -> tuple[list[Frame], list[Frame]]:
    """World frames after every module ``(K,)`` and at every joint *before* its rotation
    ``(n,)``; with a ``layout`` (:class:`Layout`), those of the reduced arm it
    describes, ``d`` ending in the segment's six parameters."""
    frame: Frame = _identity()
    ends, joints = [], []
    k = 0
    if layout is not None:
        m = d.shape[0] - 6
        free = module_transform(
            Module("segment", tuple((m + s, 0.0) for s in range(6)), 0.0), d
        )
    for i, module in enumerate(arm_modules):
        if module.kind == "joint":
            joints.append(frame)
            frame = compose(frame, module_transform(module, d, theta[k]))
            k += 1
        elif layout is None:
            frame = compose(frame, module_transform(module, d))
        else:
            frame = compose(
                frame, _select(layout.present[i], module_transform(module, d))
            )
        if layout is not None:
            frame = compose(frame, _select(layout.segment[i], free))
        ends.append(frame)
    return ends, joints


def module_bodies(arm_modules: tuple[Module, ...]) -> np.ndarray:
    """Body index carrying each module (0 = ground; joint ``k`` starts body ``k+1``)."""
    return np.cumsum([m.kind == "joint" for m in arm_modules]).astype(int)


def tool_rotation(
    arm: Arm, theta, d, layout: Layout | None = None
) -> Float[Array, "3 3"]:
    """End-effector orientation ``R_fk`` (columns: tool x, y, z = tip axis)."""
    ends, _ = chain(arm.modules, theta, d, layout)
    return rot.matrix(ends[-1][0])


# ---------------------------------------------------------------------------------
# The engine model.


def _body_origins(anchors: list, tip: np.ndarray) -> list[np.ndarray]:
    """Each body's origin at rest: the mean of the joint anchors it carries (the ground
    its first joint's; the last body its joint's and the tool tip)."""
    n = len(anchors)
    carried = [[anchors[b - 1]] if b else [] for b in range(n + 1)]
    for b in range(n):
        carried[b].append(anchors[b])
    carried[n].append(tip)
    return [np.mean(points, axis=0) for points in carried]


def _definition(
    arm_name: str,
    modules: tuple[Module, ...],
    d: np.ndarray,
    length_scale: float | None,
) -> dict:
    """The mechanism-file dictionary of the arm at design ``d`` (rest pose θ = 0).

    ``units = "m"``: arm task files are in metres (and kg, N·m; see
    :mod:`linkopt._arms.codesign.task`), which the task's gravity and torque limit
    assume, so the arm's lengths are too. Without ``length_scale`` the reference length
    is the arm's span over joint anchors and module ends (the loader's default uses
    anchors only, and a 1-joint arm has a single anchor)."""
    ends, joints = chain(
        modules,
        jnp.zeros(sum(m.kind == "joint" for m in modules)),
        jnp.asarray(d, dtype=jnp.float64),
    )
    ends = [np.asarray(p) for _, p in ends]
    anchors = [np.asarray(p) for _, p in joints]
    axes = [np.asarray(rot.matrix(q))[:, 2] for q, _ in joints]
    n = len(joints)
    if length_scale is None:
        length_scale = span(np.array(anchors + ends))
    bodies = ["base"] + [f"body{b}" for b in range(1, n + 1)]
    names = [f"j{k + 1}" for k in range(n)]
    carriers = module_bodies(modules)
    points = [(f"m{k}", int(carriers[k]), p) for k, p in enumerate(ends)]
    return chain_definition(
        arm_name,
        bodies,
        names,
        names,
        anchors,
        axes,
        points=[*points, ("tip", n, ends[-1])],
        outputs=[joint_output(j, j, -float(np.pi), float(np.pi)) for j in names],
        origins=_body_origins(anchors, ends[-1]),
        units="m",
        reference_length=length_scale,
    )


def mechanism_definition(arm: Arm, d) -> dict:
    """Mechanism-file dictionary of the arm at design ``d``, same reference length."""
    return _definition(
        arm.name, arm.modules, np.asarray(d, dtype=float), arm.mechanism.length_scale
    )


def _check_module(module: Module, k: int) -> None:
    if module.kind not in SLOTS or len(module.slots) != len(SLOTS[module.kind]):
        raise InputError(
            f"arm module {k}: expected a kind of {list(SLOTS)} with its slots, got "
            f"{module.kind!r} with {len(module.slots)} slots"
        )


def make_arm(
    name: str,
    modules: tuple[Module, ...],
    design_names,
    d0,
    lower,
    upper,
    is_length,
    torque_limit: float,
    radius: float,
    source: str = "<arm>",
) -> Arm:
    """Build an :class:`Arm` and its engine model at ``d0`` (validated by the
    loader); modules of an unknown kind or slot count are an :class:`InputError`."""
    for k, module in enumerate(modules):
        _check_module(module, k)
    d0 = np.asarray(d0, dtype=float)
    mech = build(_definition(name, modules, d0, None), source)
    return Arm(
        name,
        tuple(modules),
        tuple(design_names),
        d0,
        np.asarray(lower, float),
        np.asarray(upper, float),
        np.asarray(is_length, bool),
        float(torque_limit),
        float(radius),
        mech,
    )


def arm_geometry(
    arm: Arm, d: Float[Array, " m"], layout: Layout | None = None
) -> Geometry:
    """Engine geometry of design ``d`` (homogenised): joint anchors/axes at θ = 0,
    helper axes along each joint frame's x (⟂ to the axis and smooth in ``d``),
    module-end points."""
    mech = arm.mechanism
    n = arm.num_joints
    ends, joints = chain(arm.modules, jnp.zeros(n), d, layout)
    rotations = jnp.stack([rot.matrix(q) for q, _ in joints])
    points = jnp.stack([p for _, p in ends] + [ends[-1][1]])
    scale = mech.length_scale
    return Geometry(
        anchors=jnp.stack([p for _, p in joints]) / scale,
        axes=rotations[:, :, 2],
        helpers=rotations[:, :, 0],
        axes2=jnp.zeros((n, 3)),
        points=points / scale,
        origins=jnp.asarray(mech.body_origins / scale),
    )


def direct_state(
    arm: Arm,
    theta: Float[Array, " n"],
    d: Float[Array, " m"],
    layout: Layout | None = None,
) -> Float[Array, " S"]:
    """Maximal-coordinate state of joint angles ``θ`` (homogenised), by the chain
    product.

    The ground stays at its origin. Body ``k`` (after joint ``k``) carries the frame
    ``F_k`` just after joint ``k``, so it moves by ``G = F_k(θ) F_k(0)⁻¹``
    (:func:`linkopt._arms.chain.chain_state`).
    """
    mech = arm.mechanism
    scale = mech.length_scale
    _, moved = chain(arm.modules, theta, d, layout)
    _, rest = chain(arm.modules, jnp.zeros_like(theta), d, layout)
    origins = jnp.asarray(mech.body_origins)
    z = jnp.array([0.0, 0.0, 1.0])
    rotations = [
        rot.multiply(q, rot.from_axis_angle(z, theta[k]))
        for k, (q, _) in enumerate(moved)
    ]
    offsets = [origins[k + 1] - p for k, (_, p) in enumerate(rest)]
    ground = jnp.concatenate([origins[0] / scale, jnp.array([1.0, 0.0, 0.0, 0.0])])
    bodies = chain_state(
        rotations, [p for _, p in moved], [q for q, _ in rest], scale, offsets
    )
    return jnp.concatenate([ground, bodies])


def arm_state(
    arm: Arm,
    theta: Float[Array, " n"],
    d: Float[Array, " m"],
    layout: Layout | None = None,
) -> tuple[Geometry, Float[Array, " S"]]:
    """``(geometry, state)`` of ``(θ, d)``; the state's derivatives are the engine's
    implicit-function tangents ``ṡ = -(JᵀJ)⁻¹Jᵀ(∂C/∂a ȧ + ∂C/∂p ṗ)`` of ``C_FK``."""
    geom = arm_geometry(arm, d, layout)
    state = direct_state(arm, theta, d, layout)
    return geom, implicit_state("fk", arm.mechanism, geom, theta, state)


def arm_loads(
    arm: Arm, d: Float[Array, " m"], gravity, payload: float = 0.0
) -> tuple[np.ndarray, Float[Array, "L 3"], Float[Array, "L 3"]]:
    """Gravity loads ``(bodies (L,), rest points (L, 3), forces (L, 3))`` for
    :mod:`linkopt._engine.statics`.

    A module's mass sits midway between its input and output frame origins (a joint's
    at its axis), in the body that carries the module; the payload (kg) at the tool tip.
    """
    ends, _ = chain(arm.modules, jnp.zeros(arm.num_joints), d)
    starts = [jnp.zeros(3)] + [p for _, p in ends[:-1]]
    points = [0.5 * (a + b) for a, (_, b) in zip(starts, ends)] + [ends[-1][1]]
    masses = np.array([m.mass for m in arm.modules] + [float(payload)])
    bodies = np.append(module_bodies(arm.modules), arm.num_joints)
    forces = masses[:, None] * np.asarray(gravity, dtype=float)[None, :]
    return bodies, jnp.stack(points), jnp.asarray(forces)


def tool_pose(
    arm: Arm,
    theta: Float[Array, " n"],
    d: Float[Array, " m"],
    layout: Layout | None = None,
) -> tuple[Float[Array, 3], Float[Array, "3 3"], Geometry, Float[Array, " S"]]:
    """``FK(θ, d) = (p_fk, R_fk)`` read off the engine state (Sec. III-B), plus geometry
    and state.

    ``p_fk`` is the ``tip`` point; ``R_fk = R(q_last) R_fk(0, d)``, the last body's
    rotation applied to the tool's rest orientation (bodies are at identity orientation
    at rest). With a ``layout``, the reduced arm it describes on ``arm``'s engine model
    (:class:`Layout`).
    """
    geom, state = arm_state(arm, theta, d, layout)
    mech = arm.mechanism
    tip = homogenised_point_positions(mech, geom, state)[-1] * mech.length_scale
    q_last = state.reshape(-1, 7)[-1, 3:]
    rest = tool_rotation(arm, jnp.zeros_like(theta), d, layout)
    return tip, rot.matrix(q_last) @ rest, geom, state
