"""A mechanism's numbers: what every program takes as data (:mod:`.structure` makes
them the leaves of the mechanism's pytree), and the design classes.

A :class:`~.model.Mechanism` mixes *structure* (bodies, joint families, which body each
joint, point, motor and output belongs to, settings that shape arrays) with *numbers*
(anchors, axes, body origins, points and how they follow their bodies, output ranges,
motor limits, the reference length, the design space's map and bounds, and the
settings that are numbers: weights, steps, tolerances, iteration caps, α₋, the extra
targets' values, collision radii and band). :func:`numbers` reads them, in a fixed
order, under their dotted field paths; everything else is the mechanism's
:class:`~.structure.Structure`. So mechanisms with the same structure, e.g.
``mechanisms/delta.toml`` and ``delta_deep_box.toml`` (other output ranges), a file
whose anchors, names or ``[solver]``/``[evaluation]`` numbers were edited, share one
traced and compiled program.

Safety: a number is a tracer inside a program, so code that used it as a numpy
constant fails loudly (``TracerArrayConversionError``) instead of baking the first
mechanism's value into a program that others reuse. Structural facts that the loader
derives from numbers (which joints have an axis, each joint's helper direction, which
hull a point follows) are stored as their own fields, part of the structure.

Design classes: :func:`padded` gives a mechanism whose design space is padded with
zero columns to :func:`design_class` parameters, which :mod:`.programs` uses, so a
file that gains or loses a parameter within its class reuses every stored program.
"""

from __future__ import annotations

import dataclasses
import weakref

import numpy as np

from .model import Mechanism

#: Mechanism fields taken as data, and those of its design space and point attachment.
#: :func:`numbers` names each by its dotted path from the mechanism.
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
#: The design space's fields taken as data (:func:`padded` pads them to
#: :func:`design_class` columns: zeros, a padded parameter moves nothing;
#: ``is_length`` False).
DESIGN_FIELDS = ("p0", "lower", "upper", "matrix", "is_length")
#: The point parameters' map (``design.points``) is data too, padded like ``matrix``,
#: where a file has one. The link angles' fields (:class:`~.model.Turns`), taken as
#: data where a file has twists; ``select`` padded like the design map, the number of
#: turns part of the structure.
TURN_FIELDS = ("select", "centers", "normals", "joints")
ATTACHMENT_FIELDS = ("weights", "offsets", "spans")
#: Settings taken as data (``[solver]``, ``[evaluation]``, ``[collision]``): editing
#: a weight, a step, an iteration cap, a threshold or an extra target's values reuses
#: every program. Each is a number or an array inside a program: an iteration cap
#: bounds a ``while_loop`` (int64), ``targets`` is an ``(E, K)`` array, ``alpha_minus``
#: is NaN where the file gives none. What shapes a program stays in the structure:
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
#: one side; whether the file has any is part of the structure).
LIMIT_FIELDS = ("motor_min", "motor_max")
#: Integer settings (iteration caps), taken as int64.
INTEGER_FIELDS = frozenset(
    {"max_iterations", "ik_iterations", "adversarial_iterations"}
)
#: Each mechanism's copy with its design padded to its class (:func:`padded`).
_PADDED: weakref.WeakKeyDictionary[Mechanism, Mechanism] = weakref.WeakKeyDictionary()


def _array(value, dtype) -> np.ndarray:
    """``value`` as a numpy array of ``dtype``; a tracer (a mechanism rebuilt inside
    a program) as a ``jax.numpy`` one. A concrete JAX array becomes numpy: a
    ``jax.numpy`` conversion inside a trace would give a tracer, which a cache of a
    concrete mechanism's numbers must never keep."""
    if type(value).__module__.startswith("jax"):
        import jax

        if isinstance(value, jax.core.Tracer):
            return jax.numpy.asarray(value, dtype=dtype)
    return np.asarray(value, dtype=dtype)


def numbers(mech: Mechanism) -> dict:
    """The numbers of ``mech`` that programs take as data, by dotted field path
    (numpy arrays: float64, int64 iteration caps, bool ``design.is_length``; JAX
    arrays where the mechanism holds them)."""
    out = {name: _array(getattr(mech, name), np.float64) for name in FIELDS}
    for name in DESIGN_FIELDS:
        dtype = bool if name == "is_length" else np.float64
        out[f"design.{name}"] = _array(getattr(mech.design, name), dtype)
    turns = mech.design.turns
    if turns is not None:
        for name in TURN_FIELDS:
            out[f"design.turns.{name}"] = _array(getattr(turns, name), np.float64)
    if mech.design.points is not None:
        out["design.points"] = _array(mech.design.points, np.float64)
    for name in ATTACHMENT_FIELDS:
        out[f"point_attachment.{name}"] = _array(
            getattr(mech.point_attachment, name), np.float64
        )
    if mech.output_frames is not None:
        out["output_frames"] = _array(mech.output_frames, np.float64)
    if mech.motor_limited:
        for name in LIMIT_FIELDS:
            out[name] = _array(getattr(mech, name), np.float64)
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
        return _array(value, np.float64).reshape(len(value), mech.num_outputs)
    if name == "alpha_minus":
        return _array(np.nan if value is None else value, np.float64)
    dtype = np.int64 if name in INTEGER_FIELDS else np.float64
    return _array(value, dtype)


def padded(mech: Mechanism) -> Mechanism:
    """``mech`` with its design space padded to :func:`design_class` parameters
    (zero columns, blank names, ``is_length`` False: a padded parameter moves
    nothing); once per mechanism, weakly held."""
    held = _PADDED.get(mech)
    if held is None:
        space = mech.design
        extra = {f: padded_design(mech, getattr(space, f)) for f in DESIGN_FIELDS}
        extra["is_length"] = extra["is_length"].astype(bool)
        if space.points is not None:
            extra["points"] = padded_design(mech, space.points)
        turns = space.turns
        if turns is not None:
            extra["turns"] = dataclasses.replace(
                turns, select=padded_design(mech, turns.select)
            )
        names = space.names + ("",) * (design_class(space.size) - space.size)
        design = dataclasses.replace(space, names=names, **extra)
        held = _PADDED[mech] = dataclasses.replace(mech, design=design)
    return held
