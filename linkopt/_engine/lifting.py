"""The mechanism as data: one compiled program for every mechanism of one structure.

A :class:`~.model.Mechanism` mixes *structure* (bodies, joint families, which body each
joint, point, motor and output belongs to, settings that shape arrays) with *numbers*
(anchors, axes, body origins, points and how they follow their bodies, output ranges,
motor limits, the reference length, the design space's map and bounds, and the
settings that are numbers: weights, steps, tolerances, iteration caps, α₋, the extra
targets' values, collision radii and band). The programs of :mod:`.programs` take
the numbers as arguments, as MuJoCo MJX passes its ``Model``:

* :func:`numbers` reads them off a concrete mechanism (numpy; float64, iteration caps
  int64);
* :func:`lift` puts traced values in their place, so a program built from one
  mechanism computes with the numbers it is called with;
* :func:`structure_key` digests everything else (the numbers by shape only), so that
  mechanisms with the same structure, e.g. ``mechanisms/delta.toml`` and
  ``delta_deep_box.toml`` (other output ranges), a file whose anchors, names or
  ``[solver]``/``[evaluation]`` numbers were edited, share one traced and compiled
  program. Names enter the key by their count only.

Safety: a lifted number is a tracer, so code that used it as a numpy constant inside a
program fails loudly (``TracerArrayConversionError``) instead of baking the first
mechanism's value into a program that others reuse; every field that is not lifted is
part of the key. Structural facts that the loader derives from numbers (which joints
have an axis, each joint's helper direction, which hull a point follows) are stored
as static fields and keyed.
"""

from __future__ import annotations

import dataclasses
import hashlib
import weakref

import numpy as np

from .model import Mechanism, digest

#: Mechanism fields taken as data, and those of its design space and point attachment.
FIELDS = (
    "body_origins",
    "anchors",
    "axes",
    "axes2",
    "point_positions",
    "output_min",
    "output_max",
    "length_scale",
)
#: The design space's fields taken as data, padded to :func:`design_class` columns
#: (zeros: a padded parameter moves nothing; ``is_length`` False).
DESIGN_FIELDS = ("p0", "lower", "upper", "matrix", "is_length")
#: The point parameters' map (``design.points``) is data too, padded like ``matrix``,
#: where a file has one. The link angles' fields (:class:`~.model.Turns`), taken as
#: data where a file has twists; ``select`` padded like the design map, the number of
#: turns keyed.
TURN_FIELDS = ("select", "centers", "normals", "joints")
ATTACHMENT_FIELDS = ("weights", "offsets", "spans")
#: Settings taken as data (``[solver]``, ``[evaluation]``, ``[collision]``): editing
#: a weight, a step, an iteration cap, a threshold or an extra target's values reuses
#: every program. Each is a number or an array inside a program: an iteration cap
#: bounds a ``while_loop`` (int64), ``targets`` is an ``(E, K)`` array, ``alpha_minus``
#: is NaN where the file gives none. What shapes a program stays static and keyed:
#: ``samples_per_dimension`` and ``interior`` (the grid), the number of extra targets,
#: ``[collision].enable`` and the capsules and pairs.
SOLVER_FIELDS = ("tolerance", "max_iterations", "initial_damping")
EVALUATION_FIELDS = (
    "alpha_factor",
    "motion_weight",
    "range_weight",
    "regularizer_weight",
    "max_step",
    "ik_iterations",
    "adversarial_iterations",
    "alpha_minus",
    "targets",
)
COLLISION_FIELDS = (
    "clearance",
    "weight",
    "segment_radii",
    "body_offsets",
    "body_radii",
)
#: Motor limits, taken as data when a file has them (``inf`` where a motor has none on
#: one side; whether the file has any is static and keyed).
LIMIT_FIELDS = ("motor_min", "motor_max")
#: Integer settings (iteration caps), lifted as int64.
INTEGER_FIELDS = frozenset(
    {"max_iterations", "ik_iterations", "adversarial_iterations"}
)
#: Fields that never reach a program: names and where the file came from.
IGNORED = ("name", "source", "raw")
#: Name tuples: a program depends on how many names there are, never on the names.
NAMES = ("body_names", "joint_names", "point_names", "motor_names", "output_names")

_KEYS: weakref.WeakKeyDictionary[Mechanism, str] = weakref.WeakKeyDictionary()


def numbers(mech: Mechanism) -> dict:
    """The numbers of ``mech`` that programs take as data (numpy arrays: float64,
    int64 iteration caps, bool ``design.is_length``)."""
    out = {name: np.asarray(getattr(mech, name), dtype=np.float64) for name in FIELDS}
    for name in DESIGN_FIELDS:
        out[f"design.{name}"] = _padded_design_field(mech, name)
    turns = mech.design.turns
    if turns is not None:
        for name in TURN_FIELDS:
            value = np.asarray(getattr(turns, name), dtype=np.float64)
            if name == "select":
                value = padded_design(mech, value)
            out[f"design.turns.{name}"] = value
    if mech.design.points is not None:
        out["design.points"] = padded_design(mech, mech.design.points)
    for name in ATTACHMENT_FIELDS:
        out[f"points.{name}"] = np.asarray(
            getattr(mech.point_attachment, name), np.float64
        )
    if mech.output_frames is not None:
        out["output_frames"] = np.asarray(mech.output_frames, dtype=np.float64)
    if mech.motor_limited:
        for name in LIMIT_FIELDS:
            out[name] = np.asarray(getattr(mech, name), dtype=np.float64)
    for table, fields in _settings(mech):
        for name in fields:
            out[f"{table}.{name}"] = _setting(mech, table, name)
    return out


def design_class(size: int) -> int:
    """The number of design parameters a program is made for: ``size`` rounded up to
    4, 8, 16, 32, ... Designs enter a program padded with zeros to it
    (:func:`padded_design`), so a file that gains or loses a parameter within its
    class reuses every program; the padding costs a few zero columns of the design
    map."""
    return max(4, 1 << max(size - 1, 0).bit_length())


def padded_design(mech: Mechanism, design):
    """A design ``(..., n_p)`` (file units) padded with zeros to
    ``(..., design_class(n_p))``: what a program of :mod:`.programs` takes. numpy
    for numbers, ``jax.numpy`` for a JAX array or tracer (a call inside a user's
    ``jax.jit`` or ``jax.grad``)."""
    xp = np
    if type(design).__module__.startswith("jax"):  # jax and jaxlib arrays, tracers
        import jax.numpy as xp
    design = xp.asarray(design, dtype=xp.float64)
    extra = design_class(mech.design.size) - design.shape[-1]
    return xp.pad(design, [(0, 0)] * (design.ndim - 1) + [(0, extra)])


def _padded_design_field(mech: Mechanism, name: str) -> np.ndarray:
    """A field of the design space with its parameter axis (the last) padded."""
    value = getattr(mech.design, name)
    dtype = bool if name == "is_length" else np.float64
    return padded_design(mech, value).astype(dtype)


def _settings(mech: Mechanism) -> tuple[tuple[str, tuple[str, ...]], ...]:
    """The settings tables of ``mech`` and their fields taken as data."""
    tables = (("solver", SOLVER_FIELDS), ("evaluation", EVALUATION_FIELDS))
    if mech.collision is not None:
        tables += (("collision", COLLISION_FIELDS),)
    return tables


def _setting(mech: Mechanism, table: str, name: str) -> np.ndarray:
    """One setting as an array (:data:`SOLVER_FIELDS` and the others)."""
    value = getattr(getattr(mech, table), name)
    if name == "targets":
        return np.asarray(value, dtype=np.float64).reshape(len(value), mech.num_outputs)
    if name == "alpha_minus":
        return np.asarray(np.nan if value is None else value, dtype=np.float64)
    dtype = np.int64 if name in INTEGER_FIELDS else np.float64
    return np.asarray(value, dtype=dtype)


def lift(mech: Mechanism, values: dict) -> Mechanism:
    """``mech`` with its numbers replaced by ``values`` (as :func:`numbers` gives
    them; tracers inside a program)."""
    names = mech.design.names
    turns = mech.design.turns
    if turns is not None:
        turns = dataclasses.replace(
            turns, **{n: values[f"design.turns.{n}"] for n in TURN_FIELDS}
        )
    driven = {}
    if mech.design.points is not None:
        driven["points"] = values["design.points"]
    design = dataclasses.replace(
        mech.design,
        names=names + ("",) * (design_class(len(names)) - len(names)),
        turns=turns,
        **driven,
        **{n: values[f"design.{n}"] for n in DESIGN_FIELDS},
    )
    attachment = dataclasses.replace(
        mech.point_attachment,
        **{n: values[f"points.{n}"] for n in ATTACHMENT_FIELDS},
    )
    extra = {}
    if mech.output_frames is not None:
        extra["output_frames"] = values["output_frames"]
    if mech.motor_limited:
        extra |= {name: values[name] for name in LIMIT_FIELDS}
    for table, fields in _settings(mech):
        extra[table] = dataclasses.replace(
            getattr(mech, table), **{n: values[f"{table}.{n}"] for n in fields}
        )
    return dataclasses.replace(
        mech,
        **{n: values[n] for n in FIELDS},
        design=design,
        point_attachment=attachment,
        **extra,
    )


def _skeleton(mech: Mechanism) -> Mechanism:
    """``mech`` with every number replaced by its shape (what a program depends on)."""
    shapes = {k: f"{v.dtype.str}{v.shape}" for k, v in numbers(mech).items()}
    blank = lift(mech, shapes)
    counts = {name: len(getattr(mech, name)) for name in NAMES}
    design = dataclasses.replace(blank.design, names=len(blank.design.names))
    reported = blank.reported
    if reported is not None:
        reported = dataclasses.replace(reported, names=len(reported.names))
    welds = blank.welds  # the parts never enter a program: their map does
    return dataclasses.replace(
        blank,
        **{name: None for name in IGNORED},
        **counts,
        design=design,
        reported=reported,
        welds=None if welds is None else tuple(welds.body_of),
    )


def structure_key(mech: Mechanism) -> str:
    """Hex digest of the structure of ``mech``: equal for two mechanisms whose
    programs are the same function of their numbers."""
    key = _KEYS.get(mech)
    if key is None:
        sink = hashlib.sha256()
        digest(_skeleton(mech), sink)
        key = _KEYS[mech] = sink.hexdigest()
    return key
