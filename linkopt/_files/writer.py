"""Write a design back as a mechanism file of the same format (TOML).

The file's own tables are kept; joint anchors and axes take the design's values
(symmetric copies, ties, composed lengths and straight legs included), and every
parameter's rest value moves with them: a coordinate is read back from its anchor (an
axis component from the axis, written unnormalised: a parameter is a component of the
axis as the file writes it, and a normalised axis would read back as other values), a
length from its two joints, a radius from its joints' distance to the axis, and the
directions a length or radius moves along are the same at the written design (a length
moves along its link, a radius radially), so reloading gives the same design space with
the written design as its initial one (tests/test_design_parameters.py). Named points
given by ``position`` are written where the design puts them
(:mod:`linkopt._engine.attachment`), with their ``follow`` rule written out. The
reference length, α₋ and body frame origins of the original are written explicitly so
that the new file is homogenised and judged exactly as the design was during
optimisation. The source file's leading comment block
(its header: what the mechanism is, its units, its sources) is kept, below the
``header`` the caller gives.
"""

from __future__ import annotations

import copy
import math
from pathlib import Path

import numpy as np

from .._engine.arguments import check_design
from .._engine.geometry import geometry, moved_joints
from .._engine.model import Mechanism
from .._engine.welding import parts
from .._errors import InputError
from .._folders import write_atomic
from .points import DEFAULT_FOLLOW

#: TOML basic-string escapes; other control characters are written as ``\\uXXXX``.
_ESCAPES = {
    "\\": "\\\\",
    '"': '\\"',
    "\n": "\\n",
    "\t": "\\t",
    "\r": "\\r",
    "\b": "\\b",
    "\f": "\\f",
}


def _escaped(c: str) -> str:
    return f"\\u{ord(c):04x}" if ord(c) < 0x20 or ord(c) == 0x7F else c


def _key(k) -> str:
    """A TOML key: bare when it can be, else a quoted string."""
    k = str(k)
    return (
        k
        if k and all(c.isascii() and (c.isalnum() or c in "_-") for c in k)
        else (_value(k))
    )


def _value(v, key: str = "") -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if not math.isfinite(v):
            raise InputError(f"{key}: cannot write {v!r} to a mechanism file")
        return repr(v)
    if isinstance(v, str):
        return '"' + "".join(_ESCAPES.get(c, _escaped(c)) for c in v) + '"'
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_value(x, key) for x in v) + "]"
    if isinstance(v, dict):
        return (
            "{ "
            + ", ".join(f"{_key(k)} = {_value(x, key)}" for k, x in v.items())
            + " }"
        )
    raise InputError(
        f"{key}: cannot write a {type(v).__name__} value to a mechanism file"
    )


def dumps(data: dict) -> str:
    """TOML text of a parsed definition (tables and arrays of tables, one level
    deep)."""
    lines: list[str] = []
    for key, value in data.items():
        if isinstance(value, dict):
            lines.append(f"[{_key(key)}]")
            lines += [
                f"{_key(k)} = {_value(v, f'{key}.{k}')}" for k, v in value.items()
            ]
            lines.append("")
        elif (
            isinstance(value, list)
            and value
            and all(isinstance(x, dict) for x in value)
        ):
            for entry in value:
                lines.append(f"[[{_key(key)}]]")
                lines += [
                    f"{_key(k)} = {_value(v, f'{key}.{k}')}" for k, v in entry.items()
                ]
                lines.append("")
        else:
            lines.insert(0, f"{_key(key)} = {_value(value, key)}")
    return "\n".join(lines)


def design_definition(mech: Mechanism, design, alpha_minus: float) -> dict:
    """The parsed definition of ``mech`` with ``design`` baked into its rest
    geometry."""
    design = np.asarray(design, dtype=float)
    anchors, axes = (np.asarray(v) for v in moved_joints(mech, design))
    rest = geometry(mech, design)
    data = copy.deepcopy(mech.raw)
    data["mechanism"]["reference_length"] = float(mech.length_scale)
    for body, origin in zip(data["bodies"], parts(mech).body_origins):
        body["origin"] = [float(v) for v in origin]  # same frames, so the same f_sing
    data.setdefault("evaluation", {})["alpha_minus"] = float(alpha_minus)
    if mech.evaluation.targets:  # the file's and those an optimisation added
        data["evaluation"]["targets"] = [
            [float(v) for v in t] for t in mech.evaluation.targets
        ]
    for k, joint in enumerate(data["joints"]):
        joint["anchor"] = [float(v) for v in anchors[k]]
        if "axis" in joint:  # unnormalised: axis components read back as written
            joint["axis"] = [float(v) for v in axes[k] * _length(joint["axis"])]
        if "axis2" in joint:  # kept perpendicular to the moved axis
            joint["axis2"] = [float(v) for v in np.asarray(rest.axes2[k])]
    points = np.asarray(rest.points) * mech.length_scale
    for k, point in enumerate(data.get("points", [])):
        if "position" in point:  # where the design put it (attachment)
            point["position"] = [float(v) for v in points[k]]
            point["follow"] = point.get("follow", DEFAULT_FOLLOW)  # the rule, explicit
    return data


def source_header(mech: Mechanism) -> str:
    """The leading comment block of the file ``mech`` was loaded from (its lines up to
    the first that is neither a comment nor blank, trailing blank lines dropped), or
    ``""`` when it was not loaded from a file that is still readable."""
    try:
        text = Path(mech.source).read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError, ValueError):
        return ""
    lines = []
    for line in text.splitlines():
        if line.strip() and not line.lstrip().startswith("#"):
            break
        lines.append(line.rstrip())
    while lines and not lines[-1]:
        lines.pop()
    return "".join(f"{line}\n" for line in lines)


def _length(vector) -> float:
    """The length of an axis as the source file writes it: its axis-component
    parameters are components of that vector (:mod:`linkopt._files.design_space`),
    so the written axis keeps it and reads back as the same parameters."""
    vec = np.asarray(vector, dtype=float)
    largest = float(np.max(np.abs(vec)))
    return largest * float(np.linalg.norm(vec / largest))


def axis_note(mech: Mechanism) -> str:
    """The line a written file carries where a parameter is an axis component: its
    axes are written unnormalised on purpose (a normalised axis is another design)."""
    axes = [
        name
        for name, item in zip(mech.design.names, mech.raw.get("parameters", []))
        if str(item.get("coordinate", "")).startswith("axis_")
    ]
    if not axes:
        return ""
    return (
        f"Axes are written unnormalised: the parameters {', '.join(axes)} are "
        "components of the axes as written here (normalised, they would read back "
        "as other values)."
    )


def write_design(
    mech: Mechanism, design, alpha_minus: float, path: str | Path, header: str = ""
) -> Path:
    """Write ``design`` (``(P,)`` finite numbers) as a mechanism file that every command
    accepts; ``alpha_minus`` a finite number. ``header`` becomes comment lines at the
    top, followed by the source file's own header (:func:`source_header`)."""
    check_design(mech, design)
    if design is None:
        raise InputError("design: expected the design to write, got None")
    if not isinstance(alpha_minus, (int, float, np.floating, np.integer)) or not (
        math.isfinite(alpha_minus)
    ):
        raise InputError(f"alpha_minus: expected a finite number, got {alpha_minus!r}")
    path = Path(path)
    header = "\n".join(filter(None, [header, axis_note(mech)]))
    comment = "".join(f"# {line}\n" for line in header.splitlines())
    kept = source_header(mech)
    if comment and kept:
        comment += "#\n"
    text = comment + kept + ("\n" if comment or kept else "")
    text += dumps(design_definition(mech, design, alpha_minus))
    write_atomic(path, text)  # a reader sees the old file or the whole new one
    return path
