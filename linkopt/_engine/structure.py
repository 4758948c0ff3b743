"""The mechanism as a JAX pytree: its numbers are the leaves, its :class:`Structure`
the static rest, as MuJoCo MJX passes its ``Model``.

A :class:`~.model.Mechanism` is registered as a pytree node. Its leaves are the
numbers of :func:`.lifting.numbers` (anchors, axes, origins, points, output ranges,
motor limits, the reference length, the design space's map and bounds, the numeric
settings), in that fixed order; its auxiliary data is a :class:`Structure`: every
other field, with each number replaced by its shape and dtype and each name by an
empty string (names never reach a program, only their count). So a mechanism is an
ordinary argument of ``jax.jit``: JAX's cache keys on the tree structure, two loads
of one file (or a file whose numbers were edited) share one trace, and each call
computes with its own numbers. Inside a trace the mechanism is rebuilt from the
Structure's template with the traced numbers in their fields.

Value equality: two Structures are equal when the SHA-256 digest of their templates
(:func:`.model.digest`) is; the digest is computed once per Structure and is an
implementation detail of ``__eq__``/``__hash__`` (and of the on-disk key of
:mod:`.programs`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import weakref
from dataclasses import dataclass

import jax

from .. import _config  # noqa: F401  (float64 on before any array)
from .lifting import numbers
from .model import Mechanism, digest
from .welding import Welds

#: Fields that never reach a program: where the file came from and its parsed text.
IGNORED = {"name": "", "source": "", "raw": None}
#: Name tuples: a program sees how many names there are, never the names.
NAMES = ("body_names", "joint_names", "point_names", "motor_names", "output_names")

#: Each mechanism's leaves (on the device) and Structure, held weakly: flattening a
#: mechanism on a hot path (every ``jit`` call) is one dictionary lookup.
_FLAT: weakref.WeakKeyDictionary[Mechanism, tuple] = weakref.WeakKeyDictionary()


@dataclass(frozen=True, eq=False)
class Structure:
    """What shapes a mechanism's programs: ``template`` (the mechanism with numbers
    replaced by their shapes and names by empty strings), ``paths`` (the leaves'
    field paths, in order) and ``key`` (the template's hex digest, which ``==`` and
    ``hash`` compare)."""

    template: Mechanism
    paths: tuple[str, ...]
    key: str

    def __eq__(self, other) -> bool:
        return isinstance(other, Structure) and self.key == other.key

    def __hash__(self) -> int:
        return hash(self.key)

    def __repr__(self) -> str:
        return f"Structure({self.key[:12]}, {len(self.paths)} leaves)"


def replaced(obj, values: dict):
    """``obj`` (a dataclass) with the fields at the dotted ``paths`` of ``values``
    replaced, nested dataclasses copied as needed."""
    own, nested = {}, {}
    for path, value in values.items():
        head, _, rest = path.partition(".")
        if rest:
            nested.setdefault(head, {})[rest] = value
        else:
            own[head] = value
    for head, sub in nested.items():
        own[head] = replaced(getattr(obj, head), sub)
    return dataclasses.replace(obj, **own)


def _blank(names: tuple) -> tuple[str, ...]:
    return ("",) * len(names)


def _template(mech: Mechanism, values: dict) -> Mechanism:
    """``mech`` with numbers replaced by shape strings and names by blanks."""
    shapes = {k: f"{v.dtype.str}{tuple(v.shape)}" for k, v in values.items()}
    blank = replaced(mech, shapes)
    design = dataclasses.replace(blank.design, names=_blank(blank.design.names))
    reported = blank.reported
    if reported is not None:
        reported = dataclasses.replace(reported, names=_blank(reported.names))
    welds = blank.welds  # the parts never enter a program: their map does
    if welds is not None:
        welds = Welds(parts=None, body_of=welds.body_of)
    return dataclasses.replace(
        blank,
        **IGNORED,
        **{name: _blank(getattr(mech, name)) for name in NAMES},
        design=design,
        reported=reported,
        welds=welds,
    )


def _structure(mech: Mechanism, values: dict) -> Structure:
    template = _template(mech, values)
    sink = hashlib.sha256()
    digest(template, sink)
    return Structure(template, tuple(values), sink.hexdigest())


def flatten(mech: Mechanism) -> tuple[list, Structure]:
    """The mechanism's leaves and Structure; once per mechanism, the leaves of a
    concrete one put on the device."""
    held = _FLAT.get(mech)
    if held is None:
        values = numbers(mech)
        held = _FLAT[mech] = (_placed(list(values.values())), _structure(mech, values))
    return held


def _placed(leaves: list) -> list:
    """``leaves`` on the device where they are concrete and no trace is running (a
    ``device_put`` inside a trace gives tracers, which must not be kept)."""
    if any(isinstance(leaf, jax.core.Tracer) for leaf in leaves):
        return leaves
    placed = jax.device_put(leaves)
    concrete = not any(isinstance(leaf, jax.core.Tracer) for leaf in placed)
    return placed if concrete else leaves


def unflatten(structure: Structure, leaves) -> Mechanism:
    """The Structure's template with ``leaves`` in their fields (tracers inside a
    program; JAX's placeholders when it matches axes specifications, which flatten
    back as they came)."""
    leaves = list(leaves)
    mech = replaced(structure.template, dict(zip(structure.paths, leaves, strict=True)))
    _FLAT[mech] = (leaves, structure)  # flatten(unflatten(s, x)) is (x, s)
    return mech


def structure(mech: Mechanism) -> Structure:
    """The Structure of ``mech`` (its pytree's auxiliary data)."""
    return flatten(mech)[1]


jax.tree_util.register_pytree_node(Mechanism, flatten, unflatten)
