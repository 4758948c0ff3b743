"""The one mechanism type: static topology in numpy, design-dependent geometry as
arrays.

Conventions (used everywhere in linkopt):

* A body's state is 7 numbers ``(x, y, z, qw, qx, qy, qz)``: the world position of the
  body frame origin and the unit quaternion (``wxyz``) rotating body-local vectors to
  world. A mechanism with ``n`` bodies has the state ``s`` of shape ``(7n,)``, bodies in
  file order.
* At the rest pose every body has the identity orientation and its origin at the
  centroid of its joint anchors *in the initial design*. Body origins never move with
  the design: a design vector moves joint anchors inside the bodies, so the rest state
  is the same for every design and always assembles.
* Homogenisation (paper Sec. III): every length inside the solver (state positions,
  anchors, point-coincidence rows, linear motor values, Cartesian outputs) is divided
  by ``Mechanism.length_scale``. The state vectors returned by the API are homogenised;
  motors, outputs, joint and point positions are returned in file units.
"""

from __future__ import annotations

import dataclasses
import hashlib
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from .attachment import Attachment

if TYPE_CHECKING:
    from .symmetry import Symmetry
    from .welding import Welds

#: Residual rows per passive joint family.
JOINT_ROWS: dict[str, int] = {
    "revolute": 5,
    "spherical": 3,
    "universal": 4,
    "prismatic": 5,
    "cylindrical": 4,
    "fixed": 6,
}
#: A ``fixed`` joint inside a group of welded bodies, once the group is one body
#: (:mod:`.welding`): it joins its body to itself and gives no rows.
WELDED = "welded"
#: Joint families that carry a primary axis.
AXIAL_JOINTS = frozenset({"revolute", "universal", "prismatic", "cylindrical"})
#: Joint family a motor may drive, and whether that motor is linear.
MOTOR_JOINTS: dict[str, bool] = {"revolute": False, "prismatic": True}
#: Design-parameter coordinates: anchor position or primary-axis components.
COORDINATES = ("x", "y", "z", "axis_x", "axis_y", "axis_z")


@dataclass(frozen=True)
class SolverSettings:
    """Levenberg–Marquardt settings; ``tolerance`` bounds ``max |C|`` (homogenised).
    ``factor`` picks the FK/BK solves' factor of ``JᵀJ``: ``"auto"`` (dense below
    :data:`linkopt._engine.banded.MIN_BODIES` bodies or where the band is wide, banded
    otherwise: :func:`linkopt._engine.banded.serves`),
    ``"dense"`` or ``"banded"``; not a file key (tests set it)."""

    max_iterations: int = 60
    tolerance: float = 1e-12
    initial_damping: float = 1e-6
    factor: str = "auto"


@dataclass(frozen=True)
class EvaluationSettings:
    """Design-evaluation settings (paper Sec. IV, App. A/B), from ``[evaluation]``.

    ``alpha_factor``: α₋ as a multiple of f_sing at the initial design's rest pose (the
    paper used 1.2-4). ``motion_weight``/``range_weight``: w₁, w₂ of eq. 5.
    ``regularizer_weight``: weight of ½|p - p₀|² with lengths divided by the reference
    length. ``max_step``: the starting (and smallest) trust radius of the IK/adversarial
    minimiser, in rad or reference lengths for linear motors; it grows to 4x after steps
    it had to shorten (:mod:`linkopt._design.sampling`), and a step that jumps onto
    another assembly branch is rejected. ``alpha_minus``: an absolute α₋ that overrides
    ``alpha_factor`` (written into optimised files so that they are judged by the
    threshold they were optimised for). ``targets``: IK targets (file units) added to
    the grid's, one tuple of output values each; an optimisation's verification rounds
    add the places where its design failed ``linkopt verify``
    (:mod:`linkopt._design.run`), and its optimised file keeps them.
    """

    samples_per_dimension: int = 3
    interior: bool = True
    alpha_factor: float = 2.0
    motion_weight: float = 1.0
    range_weight: float = 1.0
    regularizer_weight: float = 1e-2
    max_step: float = 0.1
    ik_iterations: int = 40
    adversarial_iterations: int = 40
    alpha_minus: float | None = None
    targets: tuple[tuple[float, ...], ...] = ()


@dataclass(frozen=True, eq=False)
class Collision:
    """Link solids and the pairs checked for collision, from ``[collision]`` (static;
    built by :func:`linkopt._files.collision.read_collision`, distances in
    :mod:`linkopt._engine.collision`).

    ``G`` capsules, ``Q`` checked body pairs, ``C`` capsule pairs.
    ``segment_places (G, 2)``: each capsule's end places, indices into the anchors
    followed by the named points (so they follow the design). ``segment_bodies (G,)``;
    ``segment_radii (G,)`` and ``body_radii (B,)`` (file units). ``body_offsets
    (B, 3)``: each body's layer offset along the plane normal (file units; world and
    body frame agree at rest). ``pairs (Q, 2)``: checked body pairs; ``capsule_pairs
    (C, 2)``: the capsule pairs between them, ``capsule_owners (C,)`` the body pair of
    each. ``clearance``: the band (file units); ``weight``: the term's weight in
    ``f_design``; ``enabled``: ``[collision].enable``.
    """

    enabled: bool
    clearance: float
    weight: float
    segment_bodies: np.ndarray
    segment_places: np.ndarray
    segment_radii: np.ndarray
    body_offsets: np.ndarray
    body_radii: np.ndarray
    pairs: np.ndarray
    capsule_pairs: np.ndarray
    capsule_owners: np.ndarray
    #: ``(G,)`` the row of ``body_offsets`` (the layer) of each capsule where it is not
    #: ``segment_bodies``: a welded part's capsules keep their part's layer
    #: (:mod:`.welding`); None: ``segment_bodies``.
    segment_layers: np.ndarray | None = field(
        default=None, metadata={"digest": "unless set"}
    )


#: A field with this metadata is left out of :func:`digest` while it is None, so that
#: adding it changes no existing fingerprint or program key.
UNLESS_SET = {"digest": "unless set"}


@dataclass(frozen=True)
class DesignSpace:
    """Free design parameters ``p`` (after ties) and their linear map onto the geometry.

    ``geometry_flat(p) = geometry_flat(p0) + matrix @ (p - p0)``, where the flat
    geometry is ``[anchors (J,3), axes (J,3)]`` raveled, in file units (an axis moves
    by its axis-component parameters over the length of the axis as written), then
    the link angles' ``turns`` (:mod:`.design_angles`); the named points' coordinates
    that ``points`` drives are ``points0 + points @ (p - p0)``. Every other kind of
    parameter is such a linear map (:mod:`.design_space`): a ``coordinate`` drives one
    coordinate of a joint, plus its ``ties`` and its ``mirror``/``copies`` images under
    the ``[symmetry]``; a ``length`` moves the ``to`` anchors of a link along its rest
    direction (and with every move of its ``from`` anchor); a ``radius`` moves joints
    radially about an axis. Joints sharing an anchor at rest always move together, so
    every design keeps the rest pose assembled. No geometry row is driven by two
    parameters (composed length rows aside), so a written design reads back as the
    same parameter values.
    """

    names: tuple[str, ...]
    p0: np.ndarray  # (n_p,)
    lower: np.ndarray  # (n_p,)
    upper: np.ndarray  # (n_p,)
    matrix: np.ndarray  # (6 J, n_p)
    is_length: (
        np.ndarray
    )  # (n_p,) bool: an anchor coordinate (file units), not an axis component
    #: Link angles (``kind = "twist"``), the one part that is not linear; None when
    #: there are none.
    turns: Turns | None = field(default=None, metadata=UNLESS_SET)
    #: ``(3 P, n_p)``: the named points' rest coordinates that ``kind = "point"``
    #: parameters set (a coordinate a column moves is the parameter's value, and no
    #: longer follows the anchors: :func:`.following.drive`); None when there are none.
    points: np.ndarray | None = field(default=None, metadata=UNLESS_SET)

    @property
    def size(self) -> int:
        return len(self.names)


@dataclass(frozen=True)
class Turns:
    """``T`` link-angle parameters (:mod:`.design_angles`), applied after the linear
    map in order: the joints marked in ``joints[t]`` turn by ``select[t] @ (p - p0)``
    radians about the line through ``centers[t]`` along ``normals[t]`` (anchors about
    the line, axes about its direction). A turn's joints include those of the turns
    listed before it that hang from them, so a chain of link angles composes."""

    select: np.ndarray  # (T, n_p) one-hot: the parameter of each turn
    centers: np.ndarray  # (T, 3) a point of the turning line, file units
    normals: np.ndarray  # (T, 3) unit direction of the turning line
    joints: np.ndarray  # (T, J) 1.0 for the joints that turn


def per_length(is_length: np.ndarray, length_scale):
    """``length_scale`` where ``is_length``, 1 elsewhere: the divisor from file units to
    homogenised ones. numpy for a concrete length scale, JAX for a traced one (a
    program that takes the mechanism's numbers as data, :mod:`.lifting`)."""
    if isinstance(length_scale, (int, float, np.number, np.ndarray)):
        return np.where(is_length, length_scale, 1.0)
    import jax.numpy as jnp

    return jnp.where(is_length, length_scale, 1.0)


#: Output kinds and whether their values are lengths (divided by the reference length
#: inside the solver) rather than angles.
OUTPUT_KINDS: dict[str, bool] = {
    "position": True,
    "angle": False,
    "orientation": False,
    "displacement": True,
    "direction": False,
}


@dataclass(frozen=True, eq=False)
class OutputTable:
    """Static description of a list of outputs (``K`` of them), read off a state by
    :func:`linkopt._engine.constraints.table_values`.

    ``kinds``: :data:`OUTPUT_KINDS`. ``points``/``coords``: the point and coordinate
    of a position; ``joints``: the joint of an angle (``coords`` -1, or the
    Tait–Bryan angle 0..2 of a universal/spherical joint) or of a displacement
    (prismatic/cylindrical joint); ``bodies`` ``(K, 2)``: reference body and body of
    an orientation, whose Tait–Bryan angle ``coords`` is measured in the frame
    ``frames[k] = (e1, e2)``, or of a direction, whose tilt ``coords`` (0, 1) of the
    body's axis ``frames[k, 0]`` is measured about ``frames[k, 1]`` and their cross
    product (:func:`linkopt._engine.joints.direction_angles`). Unused entries are -1
    (zero for frames).
    """

    names: tuple[str, ...]
    kinds: tuple[str, ...]
    points: np.ndarray  # (K,) int
    coords: np.ndarray  # (K,) int
    joints: np.ndarray  # (K,) int
    bodies: np.ndarray  # (K, 2) int
    frames: np.ndarray  # (K, 2, 3)

    @classmethod
    def empty(cls) -> OutputTable:
        none = np.zeros(0, dtype=int)
        return cls((), (), none, none, none, np.zeros((0, 2), int), np.zeros((0, 2, 3)))

    @property
    def size(self) -> int:
        return len(self.names)

    def of(self, kind: str) -> np.ndarray:
        """Indices of the outputs of one kind (static)."""
        return np.array([k for k, t in enumerate(self.kinds) if t == kind], dtype=int)

    def scale(self, length_scale: float) -> np.ndarray:
        """Divisor from file units to homogenised units, shape ``(K,)``."""
        lengths = np.array([OUTPUT_KINDS[k] for k in self.kinds], dtype=bool)
        return per_length(lengths, length_scale)


@dataclass(frozen=True, eq=False)
class Mechanism:
    """A linkage: bodies, joints, motors, named points, outputs and design space.

    A JAX pytree (:mod:`.structure`): its numbers (:func:`.lifting.numbers`) are the
    leaves, traced inside a program, and the rest is its value-equal
    :class:`~.structure.Structure`, so it is an ordinary argument of ``jax.jit``. The
    object itself is hashed by identity (caches hold it weakly). Shapes: ``J``
    joints, ``B`` bodies, ``P`` points, ``M`` motors, ``K`` outputs.
    """

    name: str
    source: str
    body_names: tuple[str, ...]
    ground: int
    body_origins: np.ndarray  # (B, 3) file units
    joint_names: tuple[str, ...]
    joint_types: tuple[str, ...]
    joint_bodies: np.ndarray  # (J, 2) int: (i, j); a motor drives j relative to i
    anchors: np.ndarray  # (J, 3) rest anchors, initial design, file units
    axes: np.ndarray  # (J, 3) unit primary axes (zero where none)
    axes2: np.ndarray  # (J, 3) unit second axes of universal joints (zero elsewhere)
    #: (J,) bool: the joint has a primary axis (``axes`` non-zero); static, so that a
    #: program that takes the axes as data knows which are there
    axis_present: np.ndarray
    #: (J,) int: the world coordinate axis least aligned with the initial axis, from
    #: which each joint's helper axis is built (:func:`.geometry.geometry`); static
    helper_index: np.ndarray
    point_names: tuple[str, ...]
    point_bodies: np.ndarray  # (P,) int
    point_joints: np.ndarray  # (P,) int joint whose anchor the point follows, or -1
    point_positions: np.ndarray  # (P, 3) rest positions, initial design, file units
    #: how the points follow their bodies' anchors when a design moves them
    point_attachment: Attachment
    motor_names: tuple[str, ...]
    motor_joints: np.ndarray  # (M,) int
    motor_linear: np.ndarray  # (M,) bool
    output_names: tuple[str, ...]
    # "position" | "angle" | "orientation" | "displacement" | "direction" (OUTPUT_KINDS)
    output_kinds: tuple[str, ...]
    output_points: np.ndarray  # (K,) int, -1 except for positions
    output_coords: (
        np.ndarray
    )  # (K,) int: x/y/z 0..2 for positions; for angles -1 (revolute,
    # cylindrical) or the Tait–Bryan angle 0..2 of a universal/spherical joint; the
    # Tait–Bryan angle 0..2 of an orientation; -1 for displacements
    output_joints: np.ndarray  # (K,) int: the joint of angles and displacements, or -1
    output_min: np.ndarray  # (K,) file units
    output_max: np.ndarray  # (K,)
    design: DesignSpace
    length_scale: float
    solver: SolverSettings = field(default_factory=SolverSettings)
    evaluation: EvaluationSettings = field(default_factory=EvaluationSettings)
    symmetry: Symmetry | None = None  # the file's [symmetry], or None
    raw: dict = field(default_factory=dict)  # the parsed file, for writing designs back
    # Orientation outputs: (reference body, body) per output, -1 elsewhere, and the
    # frame (e1, e2) their Tait–Bryan angles are measured in (zero elsewhere). None
    # (no orientation output) reads as all -1 / zero, see :attr:`output_table`.
    output_bodies: np.ndarray | None = None  # (K, 2) int
    output_frames: np.ndarray | None = None  # (K, 2, 3)
    #: Reported outputs (``reported = true``): read off states like the outputs, but
    #: not used by BK or the design evaluation, so any number of them is allowed.
    reported: OutputTable | None = None
    #: Idle spins (:func:`linkopt._files.points.idle_spins`): bodies held only by two
    #: spherical joints, whose spin about the line through them moves nothing else,
    #: and those two joints; each gets one gauge row (:func:`~.constraints.gauge_rows`).
    idle_bodies: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=int))
    idle_joints: np.ndarray = field(  # (I, 2) int
        default_factory=lambda: np.zeros((0, 2), dtype=int)
    )
    #: Link solids and checked pairs of ``[collision]`` (None without the table).
    collision: Collision | None = field(default=None, metadata=UNLESS_SET)
    #: Motor limits ``(M,)`` (rad, or file units for linear motors, from the rest
    #: pose; ``-inf`` / ``inf`` where a motor has none on that side), None when no motor
    #: of the file has a limit: then neither enters a program or the fingerprint.
    motor_min: np.ndarray | None = field(default=None, metadata=UNLESS_SET)
    motor_max: np.ndarray | None = field(default=None, metadata=UNLESS_SET)
    #: The file's bodies when some are welded by ``fixed`` joints
    #: (:class:`.welding.Welds`, None when none is).
    welds: Welds | None = field(default=None, metadata=UNLESS_SET)

    @property
    def num_bodies(self) -> int:
        return len(self.body_names)

    @property
    def state_size(self) -> int:
        return 7 * self.num_bodies

    @property
    def num_motors(self) -> int:
        return len(self.motor_names)

    @property
    def num_outputs(self) -> int:
        return len(self.output_names)

    @property
    def motor_scale(self) -> np.ndarray:
        """Per-motor divisor from file units to homogenised units, shape ``(M,)``."""
        return per_length(self.motor_linear, self.length_scale)

    @property
    def motor_limited(self) -> bool:
        """Whether a motor of the file has a limit (static: it shapes the programs)."""
        return self.motor_min is not None

    @property
    def output_scale(self) -> np.ndarray:
        """Per-output divisor from file units to homogenised units, shape ``(K,)``."""
        return self.output_table.scale(self.length_scale)

    @property
    def output_table(self) -> OutputTable:
        """The BK outputs as an :class:`OutputTable` (static)."""
        count = len(self.output_names)
        return OutputTable(
            names=self.output_names,
            kinds=self.output_kinds,
            points=self.output_points,
            coords=self.output_coords,
            joints=self.output_joints,
            bodies=(
                np.full((count, 2), -1, dtype=int)
                if self.output_bodies is None
                else self.output_bodies
            ),
            frames=(
                np.zeros((count, 2, 3))
                if self.output_frames is None
                else self.output_frames
            ),
        )

    @property
    def reported_table(self) -> OutputTable:
        """The reported outputs (empty when the file has none)."""
        return OutputTable.empty() if self.reported is None else self.reported

    def joints_on(self, body: int) -> np.ndarray:
        """Indices of the joints that ``body`` takes part in (static), file order."""
        return np.flatnonzero((self.joint_bodies == body).any(axis=1))

    def joints_of(self, kind: str) -> np.ndarray:
        """Indices of the joints of one family (static)."""
        return np.array(
            [i for i, t in enumerate(self.joint_types) if t == kind], dtype=int
        )


def digest(value, sink) -> None:
    """Feed ``value`` into the hash ``sink``: dataclasses field by field (a field named
    ``source`` left out, and one marked :data:`UNLESS_SET` while it is None), arrays
    by dtype, shape and bytes, containers item by item,
    anything else by its ``repr``."""
    if dataclasses.is_dataclass(value) and not isinstance(value, type):
        sink.update(type(value).__name__.encode())
        for f in dataclasses.fields(value):
            unset = (
                f.metadata.get("digest") == UNLESS_SET["digest"]
                and getattr(value, f.name) is None
            )
            if f.name != "source" and not unset:
                sink.update(f.name.encode())
                digest(getattr(value, f.name), sink)
    elif isinstance(value, np.ndarray):
        sink.update(f"{value.dtype.str}{value.shape}".encode())
        sink.update(np.ascontiguousarray(value).tobytes())
    elif isinstance(value, (tuple, list)):
        sink.update(f"{type(value).__name__}{len(value)}".encode())
        for item in value:
            digest(item, sink)
    elif isinstance(value, dict):
        sink.update(f"dict{len(value)}".encode())
        for key in sorted(value, key=str):
            sink.update(repr(key).encode())
            digest(value[key], sink)
    else:
        sink.update(repr(value).encode())


def fingerprint(mech: Mechanism) -> str:
    """Hex digest of a mechanism's contents, its file path left out.

    Two loads of the same file, from any path and in any process, share it; any change
    to the file or to a field derived from it changes it. It ties an optimisation
    checkpoint to its mechanism (:mod:`linkopt._design.run`) and names a worker's
    mechanism; programs are keyed by the structure (:mod:`.structure`).
    """
    sink = hashlib.sha256()
    digest(mech, sink)
    return sink.hexdigest()
