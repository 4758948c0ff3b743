"""The mechanism as data: one compiled program for every mechanism of one structure.

A :class:`~.model.Mechanism` mixes *structure* (bodies, joint families, which body each
joint, point, motor and output belongs to, settings that shape loops) with *numbers*
(anchors, axes, body origins, points and how they follow their bodies, output ranges,
the reference length, the design space's map and bounds). The programs of
:mod:`.programs` take the numbers as arguments, as MuJoCo MJX passes its ``Model``:

* :func:`numbers` reads them off a concrete mechanism (numpy, float64);
* :func:`lift` puts traced values in their place, so a program built from one
  mechanism computes with the numbers it is called with;
* :func:`structure_key` digests everything else (the numbers by shape only), so that
  mechanisms with the same structure, e.g. ``mechanisms/delta.toml`` and
  ``delta_deep_box.toml`` (other output ranges) or a file whose anchors were edited,
  share one traced and compiled program.

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
DESIGN_FIELDS = ("p0", "lower", "upper", "matrix")
ATTACHMENT_FIELDS = ("weights", "offsets", "spans")
#: Fields that never reach a program: names and where the file came from.
IGNORED = ("name", "source", "raw")

_KEYS: weakref.WeakKeyDictionary[Mechanism, str] = weakref.WeakKeyDictionary()


def numbers(mech: Mechanism) -> dict:
    """The numbers of ``mech`` that programs take as data (float64 numpy arrays)."""
    out = {name: np.asarray(getattr(mech, name), dtype=np.float64) for name in FIELDS}
    for name in DESIGN_FIELDS:
        out[f"design.{name}"] = np.asarray(getattr(mech.design, name), np.float64)
    for name in ATTACHMENT_FIELDS:
        out[f"points.{name}"] = np.asarray(
            getattr(mech.point_attachment, name), np.float64
        )
    if mech.output_frames is not None:
        out["output_frames"] = np.asarray(mech.output_frames, dtype=np.float64)
    return out


def lift(mech: Mechanism, values: dict) -> Mechanism:
    """``mech`` with its numbers replaced by ``values`` (as :func:`numbers` gives
    them; tracers inside a program)."""
    design = dataclasses.replace(
        mech.design, **{n: values[f"design.{n}"] for n in DESIGN_FIELDS}
    )
    attachment = dataclasses.replace(
        mech.point_attachment,
        **{n: values[f"points.{n}"] for n in ATTACHMENT_FIELDS},
    )
    extra = {}
    if mech.output_frames is not None:
        extra["output_frames"] = values["output_frames"]
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
    return dataclasses.replace(blank, **{name: None for name in IGNORED})


def structure_key(mech: Mechanism) -> str:
    """Hex digest of the structure of ``mech``: equal for two mechanisms whose
    programs are the same function of their numbers."""
    key = _KEYS.get(mech)
    if key is None:
        sink = hashlib.sha256()
        digest(_skeleton(mech), sink)
        key = _KEYS[mech] = sink.hexdigest()
    return key
