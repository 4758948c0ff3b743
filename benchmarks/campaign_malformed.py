"""A seeded campaign of malformed inputs a user could hit, run through the CLI.

Cases are built from the shipped files in ``mechanisms/`` (and a few from
``tests/data``): mutations of the TOML (missing keys, wrong types, non-finite and
absurd numbers, empty arrays and tables, unknown keys and joint types, duplicated or
dangling names, self-joints, disconnected bodies, settings tables of the wrong type or
out of range, inverted design bounds, files that are not TOML) and misuse of the
command line (``--motors``/``--outputs``/``--design`` of the wrong count, NaN or text,
bad ``--out`` paths, flags out of range) over ``check``, ``fk``, ``bk``, ``evaluate``,
``export`` and ``plot``. Each case runs ``python -m linkopt`` in a fresh process under
a timeout and is classified (``docs/reference/cli.md``, "Exit status"):

* ``clean``: the expected exit status (2 for bad input; 1 where a solve may fail, for
  ``fk``/``bk`` values out of reach; 0 for the few inputs that are odd but valid, such
  as ``-0.0``) and, for 1 and 2, a one-line ``linkopt...: error: ...`` on stderr that
  names the file, field or flag, with no traceback;
* ``traceback``: a Python traceback in the output, or exit 3 (``linkopt: internal
  error``, whose traceback ``--debug`` shows: the case is rerun with it);
* ``hang``: the timeout (60 s; 180 s for ``evaluate``);
* ``wrong code``: exit 0 on a malformed input, an unexpected status, or a file
  written outside ``--out``;
* ``unclear``: the expected status without the one-line message naming what is wrong.

Run: ``python benchmarks/campaign_malformed.py [--seed 0] [--only SUBSTRING]``; it
prints the counts per class and per command and every non-clean case, and writes them
to ``benchmarks/results/campaign_malformed.json``. Cases run one at a time. The counts
before a fix come from an export of the earlier tree::

    git archive main linkopt | tar -x -C /tmp/before
    python benchmarks/campaign_malformed.py --source /tmp/before --label _before
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import os
import random
import re
import subprocess
import sys
import tempfile
import time
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
import _results  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
TIMEOUT = 60
EVALUATE_TIMEOUT = 180
CLASSES = ("clean", "traceback", "hang", "wrong code", "unclear")


@dataclass
class Case:
    """One run of the CLI: ``argv`` after ``linkopt``; ``{file}`` is replaced by the
    case's mechanism file (written from ``text``) and ``{tmp}`` by its folder."""

    name: str
    command: str
    argv: list[str]
    text: str | bytes | None = None
    expect: tuple[int, ...] = (2,)
    names: tuple[str, ...] = ()  # one of these must appear in the message
    timeout: int = TIMEOUT
    extra: dict = field(default_factory=dict)


# -- a small TOML writer (tomllib only reads) ----------------------------------------


def _key(k: str) -> str:
    return k if re.fullmatch(r"[A-Za-z0-9_-]+", k) else json.dumps(k)


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def dumps(doc: dict) -> str:
    """``doc`` as TOML: scalars and inline values first, then tables and arrays of
    tables (their nested tables inline)."""
    head, tail = [], []
    for k, v in doc.items():
        if isinstance(v, dict):
            tail.append(f"\n[{_key(k)}]")
            tail += [f"{_key(a)} = {_value(b)}" for a, b in v.items()]
        elif isinstance(v, list) and v and all(isinstance(x, dict) for x in v):
            for entry in v:
                tail.append(f"\n[[{_key(k)}]]")
                tail += [f"{_key(a)} = {_value(b)}" for a, b in entry.items()]
        else:
            head.append(f"{_key(k)} = {_value(v)}")
    return "\n".join(head + tail) + "\n"


# -- base files -----------------------------------------------------------------------

BASES = {
    "four_bar": "mechanisms/four_bar.toml",
    "five_bar": "mechanisms/five_bar.toml",
    "slider_crank": "mechanisms/slider_crank.toml",
    "delta": "mechanisms/delta.toml",
    "collision": "mechanisms/four_bar_collision.toml",
    "finger": "mechanisms/finger.toml",
    "delta_lengths": "tests/data/delta_lengths.toml",
    "all_families": "tests/data/all_families.toml",
}


def base(name: str) -> dict:
    return tomllib.loads((ROOT / BASES[name]).read_text())


def _motors_arg(doc: dict) -> str:
    return ",".join(["0.01"] * len(doc.get("motors", [])) or ["0.01"])


def _outputs_arg(doc: dict) -> str:
    mids = [
        0.5 * (o["min"] + o["max"])
        for o in doc.get("outputs", [])
        if not o.get("reported") and "min" in o and "max" in o
    ]
    return ",".join(repr(float(m)) for m in mids) or "0"


def _set(doc: dict, path: tuple, value) -> dict:
    doc = copy.deepcopy(doc)
    at = doc
    for p in path[:-1]:
        at = at[p]
    at[path[-1]] = value
    return doc


def _del(doc: dict, path: tuple) -> dict:
    doc = copy.deepcopy(doc)
    at = doc
    for p in path[:-1]:
        at = at[p]
    del at[path[-1]]
    return doc


def _append(doc: dict, table: str, entry: dict) -> dict:
    doc = copy.deepcopy(doc)
    doc.setdefault(table, []).append(entry)
    return doc


def _field_name(path: tuple) -> str:
    """The name a message should give: the last key of ``path``."""
    last = [p for p in path if isinstance(p, str)]
    return last[-1] if last else ""


# -- TOML mutations -------------------------------------------------------------------


def toml_mutations(rng: random.Random) -> list[tuple[str, str, dict, tuple[str, ...]]]:
    """(name, base, mutated document, names one of which the message should give)."""
    out: list[tuple[str, str, dict, tuple[str, ...]]] = []

    def add(name, b, doc, *names):
        out.append((name, b, doc, names))

    fb, five, delta = base("four_bar"), base("five_bar"), base("delta")
    sc, col, fin = base("slider_crank"), base("collision"), base("finger")
    dl, fam = base("delta_lengths"), base("all_families")
    k = rng.randrange(len(fb["joints"]))

    # missing required keys
    for b, doc, path in [
        ("four_bar", fb, ("mechanism", "name")),
        ("four_bar", fb, ("mechanism", "ground")),
        ("four_bar", fb, ("mechanism",)),
        ("four_bar", fb, ("bodies",)),
        ("four_bar", fb, ("joints",)),
        ("four_bar", fb, ("motors",)),
        ("four_bar", fb, ("outputs",)),
        ("four_bar", fb, ("joints", k, "type")),
        ("four_bar", fb, ("joints", k, "bodies")),
        ("four_bar", fb, ("joints", k, "anchor")),
        ("four_bar", fb, ("joints", k, "axis")),
        ("four_bar", fb, ("joints", k, "name")),
        ("four_bar", fb, ("bodies", 1, "name")),
        ("four_bar", fb, ("motors", 0, "joint")),
        ("four_bar", fb, ("outputs", 0, "min")),
        ("four_bar", fb, ("outputs", 0, "max")),
        ("four_bar", fb, ("points", 0, "body")),
        ("four_bar", fb, ("parameters", 0, "min")),
        ("four_bar", fb, ("parameters", 0, "coordinate")),
        ("five_bar", five, ("symmetry", "point")),
        ("five_bar", five, ("parameters", 0, "joint")),
        ("delta", delta, ("parameters", 0, "body")),
        ("delta", delta, ("symmetry", "order")),
        ("slider_crank", sc, ("joints", 3, "axis")),
    ]:
        add(
            f"missing {'.'.join(map(str, path))}", b, _del(doc, path), _field_name(path)
        )

    # wrong types
    a = ("joints", k, "anchor")
    for b, doc, path, value, what in [
        ("four_bar", fb, a + (0,), "1.0", "string for number"),
        ("four_bar", fb, a, {"x": 1.0, "y": 2.0, "z": 0.0}, "table for array"),
        ("four_bar", fb, a, [1.0, 2.0], "array of length 2"),
        ("four_bar", fb, a, [1.0, 2.0, 3.0, 4.0], "array of length 4"),
        ("four_bar", fb, a, [[1.0], [2.0], [3.0]], "nested arrays"),
        ("four_bar", fb, a, "0,0,0", "string for array"),
        ("four_bar", fb, a + (1,), True, "boolean for number"),
        ("four_bar", fb, a + (1,), 9223372036854775807, "int64 max"),
        ("four_bar", fb, ("joints", k, "bodies"), ["ground"], "one body"),
        ("four_bar", fb, ("joints", k, "bodies"), "ground,crank", "string bodies"),
        ("four_bar", fb, ("joints", k, "bodies"), ["a", "b", "c"], "three bodies"),
        ("four_bar", fb, ("joints", k, "bodies"), [1, 2], "numbers for bodies"),
        ("four_bar", fb, ("joints", k, "type"), 5, "number for type"),
        ("four_bar", fb, ("joints", k, "name"), 7, "number for name"),
        ("four_bar", fb, ("mechanism", "name"), ["four"], "array for name"),
        ("four_bar", fb, ("mechanism", "units"), 1, "number for units"),
        ("four_bar", fb, ("mechanism", "reference_length"), "80", "string length"),
        ("four_bar", fb, ("outputs", 0, "min"), "-0.2", "string for min"),
        ("four_bar", fb, ("outputs", 0, "reported"), "yes", "string for bool"),
        ("four_bar", fb, ("parameters", 0, "max"), [70.0], "array for max"),
        ("four_bar", fb, ("points", 0, "position"), {"x": 1}, "table for position"),
        ("four_bar", fb, ("motors", 0), "A", "string for motor table"),
        ("four_bar", fb, ("bodies",), {"name": "ground"}, "table for bodies"),
        ("four_bar", fb, ("bodies",), ["ground", "crank"], "strings for bodies"),
        ("four_bar", fb, ("joints",), {"A": 1}, "table for joints"),
        ("four_bar", fb, ("mechanism",), "four-bar", "string for [mechanism]"),
        ("five_bar", five, ("parameters", 0, "mirror"), 3, "number for mirror"),
        ("five_bar", five, ("evaluation", "alpha_factor"), "3", "string factor"),
        ("five_bar", five, ("symmetry", "normal"), [1.0, 0.0], "normal of length 2"),
        ("delta", delta, ("symmetry", "order"), 3.0, "float for order"),
        ("delta", delta, ("parameters", 0, "to"), {"a": 1}, "table for to"),
        ("delta_lengths", dl, ("bodies", 1, "anchors"), [1, 2], "array for anchors"),
        ("delta_lengths", dl, ("bodies", 2, "orientation"), [1.0, 0.0], "short quat"),
        ("delta_lengths", dl, ("mechanism", "assemble"), "true", "string assemble"),
    ]:
        add(
            f"wrong type {'.'.join(map(str, path))}: {what}",
            b,
            _set(doc, path, value),
            _field_name(path),
        )

    add(
        "integers for an axis (valid: TOML integers read as numbers)",
        "four_bar",
        _set(fb, ("joints", k, "axis"), [0, 0, 1]),
        "VALID",
    )

    # numbers: NaN, infinities, huge, -0, negative
    numbers = [
        ("nan", math.nan),
        ("inf", math.inf),
        ("-inf", -math.inf),
        ("1e308", 1e308),
        ("-1e308", -1e308),
        ("1e300", 1e300),
        ("tiny 1e-320", 1e-320),
    ]
    for label, v in numbers:
        # a finite anchor may move the joint out of a design parameter's bounds
        add(
            f"anchor x = {label}",
            "four_bar",
            _set(fb, a + (0,), v),
            "anchor",
            f"of {fb['joints'][k]['name']}.x",
        )
        # [0, 0, 1e308] is the direction z: a valid axis (it is scaled before its norm)
        finite = math.isfinite(v) and abs(v) > 1e-300
        add(
            f"axis z = {label}",
            "four_bar",
            _set(fb, ("joints", k, "axis", 2), v),
            *(("VALID",) if finite else ("axis",)),
        )
    for label, v in numbers[:4]:
        add(
            f"outputs[0].max = {label}",
            "four_bar",
            _set(fb, ("outputs", 0, "max"), v),
            "max",
        )
        add(
            f"parameters[0].min = {label}",
            "four_bar",
            _set(fb, ("parameters", 0, "min"), v),
            "min",
        )
        add(
            f"reference_length = {label}",
            "four_bar",
            _set(fb, ("mechanism", "reference_length"), v),
            "reference_length",
        )
        add(
            f"points[0].position y = {label}",
            "four_bar",
            _set(fb, ("points", 0, "position", 1), v),
            "position",
        )
    # a valid direction (1, 1, 0) that locks the planar loop: mobility 0
    add(
        "axis = [1e308, 1e308, 0]",
        "four_bar",
        _set(fb, ("joints", k, "axis"), [1e308, 1e308, 0.0]),
        "axis",
        "mobility",
    )
    add(
        "axis = [1e-200, 0, 0]",
        "four_bar",
        _set(fb, ("joints", k, "axis"), [1e-200, 0.0, 0.0]),
        "axis",
    )
    add(
        "axis = [0, 0, 0]",
        "four_bar",
        _set(fb, ("joints", k, "axis"), [0.0] * 3),
        "axis",
    )
    add(
        "reference_length = -80",
        "four_bar",
        _set(fb, ("mechanism", "reference_length"), -80.0),
        "reference_length",
    )
    add(
        "reference_length = 0",
        "four_bar",
        _set(fb, ("mechanism", "reference_length"), 0.0),
        "reference_length",
    )
    add(
        "delta symmetry order = 0",
        "delta",
        _set(delta, ("symmetry", "order"), 0),
        "order",
    )
    add(
        "delta symmetry order = -3",
        "delta",
        _set(delta, ("symmetry", "order"), -3),
        "order",
    )
    add(
        "delta symmetry order = 10**6",
        "delta",
        _set(delta, ("symmetry", "order"), 10**6),
        "order",
    )
    add(
        "delta symmetry axis = nan",
        "delta",
        _set(delta, ("symmetry", "axis"), [0.0, 0.0, math.nan]),
        "axis",
    )
    add(
        "delta length parameter min = -50",
        "delta",
        _set(delta, ("parameters", 0, "min"), -50.0),
        "min",
    )
    add(
        "output angle range 1e6 rad",
        "four_bar",
        _set(_set(fb, ("outputs", 0, "min"), -1e6), ("outputs", 0, "max"), 1e6),
        "max",
        "min",
    )
    add(
        "five_bar anchors 1e13",
        "five_bar",
        _set(five, ("joints", 4, "anchor"), [0.0, 1e13, 0.0]),
        "anchor",
    )
    add(
        "quaternion nan",
        "delta_lengths",
        _set(dl, ("bodies", 2, "orientation"), [math.nan, 0.0, 0.0, 1.0]),
        "orientation",
    )
    add(
        "quaternion zero",
        "delta_lengths",
        _set(dl, ("bodies", 2, "orientation"), [0.0, 0.0, 0.0, 0.0]),
        "orientation",
    )
    add(
        "length = -180",
        "delta_lengths",
        _set(dl, ("lengths", 0, "length"), -180.0),
        "length",
    )
    add(
        "length = 1e308",
        "delta_lengths",
        _set(dl, ("lengths", 0, "length"), 1e308),
        "length",
    )
    # -0.0 and a signed zero axis component: valid
    for name, doc in [
        ("anchor x = -0.0 (valid)", _set(fb, ("joints", 0, "anchor", 0), -0.0)),
        ("axis x = -0.0 (valid)", _set(fb, ("joints", k, "axis", 0), -0.0)),
    ]:
        out.append((name, "four_bar", doc, ("VALID",)))

    # empty arrays and tables
    for b, doc, path, value in [
        ("four_bar", fb, ("bodies",), []),
        ("four_bar", fb, ("joints",), []),
        ("four_bar", fb, ("motors",), []),
        ("four_bar", fb, ("outputs",), []),
        ("four_bar", fb, ("points",), []),
        ("four_bar", fb, ("parameters",), []),
        ("four_bar", fb, ("mechanism",), {}),
        ("four_bar", fb, ("joints", k, "anchor"), []),
        ("four_bar", fb, ("joints", k, "bodies"), []),
        ("four_bar", fb, ("joints", k), {}),
        ("four_bar", fb, ("outputs", 0), {}),
        ("five_bar", five, ("symmetry",), {}),
        ("five_bar", five, ("evaluation",), {}),
        ("five_bar", five, ("evaluation", "targets"), [[]]),
        ("five_bar", five, ("parameters", 0, "mirror"), []),
        ("collision", col, ("collision",), {}),
        ("collision", col, ("collision", "exclude"), [[]]),
        ("delta", delta, ("parameters", 0, "to"), []),
        ("delta", delta, ("parameters", 0, "copies"), []),
        ("delta_lengths", dl, ("bodies", 1, "anchors"), {}),
        ("delta_lengths", dl, ("lengths",), []),
    ]:
        valid = path in [
            ("points",),
            ("parameters",),
            ("evaluation",),
            ("collision",),
            ("lengths",),
        ]
        add(
            f"empty {'.'.join(map(str, path))}",
            b,
            _set(doc, path, value),
            "VALID" if valid else _field_name(path) or "bodies",
        )

    # unknown keys, tables, joint types
    add(
        "unknown top-level table [foo]", "four_bar", _set(fb, ("foo",), {"a": 1}), "foo"
    )
    add(
        "unknown key joints[k].color",
        "four_bar",
        _set(fb, ("joints", k, "color"), "red"),
        "color",
    )
    add(
        "misspelt [mechanism].nme",
        "four_bar",
        _set(_del(fb, ("mechanism", "name")), ("mechanism", "nme"), "x"),
        "nme",
        "name",
    )
    add(
        "unknown key [solver].tol",
        "four_bar",
        _set(fb, ("solver",), {"tol": 1e-9}),
        "tol",
    )
    add(
        "unknown key [evaluation].samples",
        "five_bar",
        _set(five, ("evaluation", "samples"), 3),
        "samples",
    )
    add(
        "unknown key [collision].thicknes",
        "collision",
        _set(col, ("collision", "thicknes"), 3.0),
        "thicknes",
    )
    add(
        "unknown key [symmetry].plane",
        "five_bar",
        _set(five, ("symmetry", "plane"), "yz"),
        "plane",
    )
    for t in ["hinge", "", "REVOLUTE", "revolute ", "ball"]:
        add(f"joint type {t!r}", "four_bar", _set(fb, ("joints", k, "type"), t), "type")
    add(
        "output kind 'speed'",
        "four_bar",
        _set(fb, ("outputs", 0, "kind"), "speed"),
        "kind",
    )
    add(
        "parameter kind 'angle'",
        "four_bar",
        _set(fb, ("parameters", 0, "kind"), "angle"),
        "kind",
    )
    add(
        "symmetry kind 'glide'",
        "five_bar",
        _set(five, ("symmetry", "kind"), "glide"),
        "kind",
    )
    add(
        "coordinate 'w'",
        "four_bar",
        _set(fb, ("parameters", 0, "coordinate"), "w"),
        "coordinate",
    )
    add(
        "output coordinate 'X'",
        "four_bar",
        _set(fb, ("outputs", 1, "coordinate"), "X"),
        "coordinate",
    )

    # duplicated and dangling names
    for table, key in [
        ("bodies", "name"),
        ("joints", "name"),
        ("motors", "name"),
        ("outputs", "name"),
        ("parameters", "name"),
    ]:
        doc = (
            _set(fb, (table, 1, key), fb[table][0][key]) if len(fb[table]) > 1 else None
        )
        if doc is None:
            doc = _append(fb, table, copy.deepcopy(fb[table][0]))
        add(f"duplicate {table} name", "four_bar", doc, table, "name")
    add(
        "duplicate points name",
        "four_bar",
        _append(fb, "points", copy.deepcopy(fb["points"][0])),
        "points",
    )
    add(
        "second motor on the same joint",
        "five_bar",
        _set(five, ("motors", 1, "joint"), five["motors"][0]["joint"]),
        "motors",
    )
    for b, doc, path, value in [
        ("four_bar", fb, ("mechanism", "ground"), "earth"),
        ("four_bar", fb, ("joints", k, "bodies", 1), "nobody"),
        ("four_bar", fb, ("motors", 0, "joint"), "Z"),
        ("four_bar", fb, ("points", 0, "body"), "nobody"),
        ("four_bar", fb, ("outputs", 0, "joint"), "Z"),
        ("four_bar", fb, ("outputs", 1, "point"), "nowhere"),
        ("four_bar", fb, ("parameters", 0, "joint"), "Z"),
        ("five_bar", five, ("parameters", 0, "mirror"), "Z"),
        ("five_bar", five, ("points", 0, "joint"), "base_left"),
        ("delta", delta, ("parameters", 0, "body"), "nobody"),
        ("delta", delta, ("parameters", 0, "from"), "Z"),
        ("delta", delta, ("parameters", 0, "copies"), ["arm2", "nobody"]),
        ("collision", col, ("collision", "exclude"), [["crank", "nobody"]]),
        ("collision", col, ("collision", "include"), [["crank", "crank"]]),
        ("collision", col, ("parameters", 0, "ties", 0, "joint"), "Z"),
        ("delta_lengths", dl, ("lengths", 0, "joints"), ["wrist1a", "Z"]),
        ("delta_lengths", dl, ("bodies", 1, "anchors", "Z"), [0.0, 0.0, 0.0]),
    ]:
        add(
            f"dangling {'.'.join(map(str, path))} = {value!r}",
            b,
            _set(doc, path, value),
            _field_name(path),
        )

    # topology
    add(
        "joint joining a body to itself",
        "four_bar",
        _set(fb, ("joints", k, "bodies"), ["crank", "crank"]),
        "bodies",
    )
    add(
        "ground joint to itself",
        "four_bar",
        _set(fb, ("joints", 0, "bodies"), ["ground", "ground"]),
        "bodies",
    )
    add(
        "body with no joints",
        "four_bar",
        _append(fb, "bodies", {"name": "loose"}),
        "loose",
    )
    island = _append(_append(fb, "bodies", {"name": "i1"}), "bodies", {"name": "i2"})
    island = _append(
        island,
        "joints",
        {
            "name": "I",
            "type": "revolute",
            "bodies": ["i1", "i2"],
            "anchor": [200.0, 0.0, 0.0],
            "axis": [0.0, 0.0, 1.0],
        },
    )
    add("two-body island", "four_bar", island, "i1", "i2")
    add(
        "motor removed (mobility 1, 0 motors)",
        "four_bar",
        _set(fb, ("motors",), []),
        "motors",
    )
    add(
        "extra motor (mobility 1, 2 motors)",
        "four_bar",
        _append(fb, "motors", {"name": "m2", "joint": "D"}),
        "motor",
    )
    add(
        "motor on a spherical joint",
        "delta",
        _set(delta, ("motors", 0, "joint"), _first(delta, "spherical")),
        "joint",
    )
    add(
        "all outputs reported",
        "four_bar",
        _set(fb, ("outputs", 0, "reported"), True),
        "outputs",
    )
    add(
        "universal axis2 parallel to axis",
        "all_families",
        _universal_parallel(fam),
        "axis2",
    )
    add("chain of 1000 bodies", "four_bar", _chain(1000), "bodies")
    add("chain of 301 bodies", "four_bar", _chain(301), "bodies")

    # settings tables
    for b, doc, table in [
        ("four_bar", fb, "solver"),
        ("five_bar", five, "evaluation"),
        ("five_bar", five, "symmetry"),
        ("collision", col, "collision"),
    ]:
        for label, v in [
            ("5", 5),
            ("'x'", "x"),
            ("[1, 2]", [1, 2]),
            ("[[t]] array", [{"a": 1}]),
            ("true", True),
        ]:
            add(f"[{table}] = {label}", b, _set(doc, (table,), v), table)
    for b, doc, path, value in [
        ("four_bar", fb, ("solver",), {"max_iterations": 0}),
        ("four_bar", fb, ("solver",), {"max_iterations": 10**9}),
        ("four_bar", fb, ("solver",), {"max_iterations": 60.5}),
        ("four_bar", fb, ("solver",), {"tolerance": 0.0}),
        ("four_bar", fb, ("solver",), {"tolerance": math.nan}),
        ("four_bar", fb, ("solver",), {"tolerance": 1.0}),
        ("four_bar", fb, ("solver",), {"initial_damping": -1.0}),
        ("five_bar", five, ("evaluation", "samples_per_dimension"), 1),
        ("five_bar", five, ("evaluation", "samples_per_dimension"), 1000),
        ("five_bar", five, ("evaluation", "alpha_factor"), -3.0),
        ("five_bar", five, ("evaluation", "alpha_minus"), math.inf),
        ("five_bar", five, ("evaluation", "max_step"), 0.0),
        ("five_bar", five, ("evaluation", "ik_iterations"), -1),
        ("five_bar", five, ("evaluation", "interior"), 1),
        ("five_bar", five, ("evaluation", "targets"), [[0.0]]),
        ("five_bar", five, ("evaluation", "targets"), [[1e9, 50.0]]),
        ("five_bar", five, ("evaluation", "targets"), [[math.nan, 50.0]]),
        ("five_bar", five, ("evaluation", "targets"), "0,50"),
        ("collision", col, ("collision", "thickness"), -1.0),
        ("collision", col, ("collision", "thickness"), 1e308),
        ("collision", col, ("collision", "clearance"), math.nan),
        ("collision", col, ("collision", "weight"), -1.0),
        ("collision", col, ("collision", "normal"), [0.0, 0.0, 0.0]),
        ("collision", col, ("collision", "enable"), "yes"),
        ("collision", col, ("bodies", 1, "radius"), -2.0),
        ("collision", col, ("bodies", 1, "layer"), 1e9),
        ("five_bar", five, ("symmetry", "normal"), [0.0, 0.0, 0.0]),
    ]:
        add(
            f"{'.'.join(map(str, path))} = {value!r}",
            b,
            _set(doc, path, value),
            _field_name(path) if len(path) > 1 else next(iter(value)),
        )

    add(
        "[symmetry].normal = [0, 1, 0]: the twins are no mirror images",
        "five_bar",
        _set(five, ("symmetry", "normal"), [0.0, 1.0, 0.0]),
        "normal",
        "mirror",
    )

    # design bounds
    p0 = fb["parameters"][0]
    add(
        "parameters min > max",
        "four_bar",
        _set(
            _set(fb, ("parameters", 0, "min"), p0["max"]),
            ("parameters", 0, "max"),
            p0["min"],
        ),
        "min",
        "max",
    )
    add(
        "parameters min == max == p0",
        "four_bar",
        _set(_set(fb, ("parameters", 0, "min"), 60.0), ("parameters", 0, "max"), 60.0),
        "VALID",
        "min",
        "max",
    )
    add("p0 below min", "four_bar", _set(fb, ("parameters", 0, "min"), 65.0), "min")
    add("p0 above max", "four_bar", _set(fb, ("parameters", 0, "max"), 55.0), "max")
    add("outputs min == max", "four_bar", _set(fb, ("outputs", 0, "max"), -0.2), "max")
    add("outputs min > max", "four_bar", _set(fb, ("outputs", 0, "max"), -1.0), "max")
    add(
        "two parameters drive one coordinate",
        "four_bar",
        _set(fb, ("parameters", 1, "joint"), "D"),
        "parameters",
        "D",
    )
    add(
        "finger parameter bounds swapped",
        "finger",
        _set(
            _set(fin, ("parameters", 3, "min"), fin["parameters"][3]["max"]),
            ("parameters", 3, "max"),
            fin["parameters"][3]["min"],
        ),
        "min",
        "max",
    )
    out += _name_and_unit_mutations(fb, delta)
    return out


def _renamed(doc: dict, old: str, new: str) -> dict:
    """``doc`` with the body ``old`` renamed ``new`` everywhere it is referred to."""
    text = json.dumps(doc).replace(json.dumps(old), json.dumps(new))
    return json.loads(text)


def _name_and_unit_mutations(fb: dict, delta: dict) -> list:
    """Names a file system or an XML file cannot hold as given, and units."""
    out = []
    # any name is valid in the file (only an stl export makes files of them)
    for name in ["../../evil", "a/b", "..", 'a<b&c"d', "a\nb", "x" * 100_000]:
        out.append(
            (
                f"body named {name[:20]!r} (valid)",
                "four_bar",
                _renamed(fb, "crank", name),
                ("VALID",),
            )
        )
    out.append(
        (
            "mechanism name with a newline",
            "four_bar",
            _set(fb, ("mechanism", "name"), "four\nbar"),
            ("VALID",),
        )
    )
    # units are informational but for export (an export case of its own, below)
    for units in ["parsec", "", "MM", "mm "]:
        out.append(
            (
                f"units = {units!r}",
                "four_bar",
                _set(fb, ("mechanism", "units"), units),
                ("units",) if units == "" else ("VALID",),
            )
        )
    out.append(
        (
            "all anchors at the origin",
            "four_bar",
            _set(
                fb, ("joints",), [j | {"anchor": [0.0, 0.0, 0.0]} for j in fb["joints"]]
            ),
            ("anchor", "reference_length", "parameters"),
        )
    )
    twin = copy.deepcopy(fb["joints"][0]) | {"name": "A2"}
    # a redundant joint: the same mechanism, mobility 1
    out.append(
        (
            "a second joint between the same bodies (valid)",
            "four_bar",
            _append(fb, "joints", twin),
            ("VALID",),
        )
    )
    out.append(
        (
            "every joint fixed",
            "four_bar",
            _set(fb, ("joints",), [j | {"type": "fixed"} for j in fb["joints"]]),
            ("motors", "mobility", "joint"),
        )
    )
    orientation = {
        "name": "o",
        "kind": "orientation",
        "body": "rocker",
        "angle": "yaw",
        "axis": [1.0, 0.0, 0.0],
        "axis2": [1.0, 0.0, 0.0],
        "min": -0.2,
        "max": 0.5,
    }
    out.append(
        (
            "orientation output with axis2 = axis",
            "four_bar",
            _set(fb, ("outputs", 0), orientation),
            ("axis2",),
        )
    )
    out.append(
        (
            "angle = 2 at a revolute joint",
            "four_bar",
            _set(fb, ("outputs", 0, "angle"), 2),
            ("angle",),
        )
    )
    out.append(
        (
            "axis_x parameter on a spherical joint",
            "delta",
            _set(
                _set(
                    delta,
                    ("parameters", 0),
                    {
                        "name": "ax",
                        "joint": _first(delta, "spherical"),
                        "coordinate": "axis_x",
                        "min": -1.0,
                        "max": 1.0,
                    },
                ),
                ("parameters", 1),
                {
                    "name": "bx",
                    "joint": "shoulder1",
                    "coordinate": "y",
                    "min": -1.0,
                    "max": 1.0,
                },
            ),
            ("coordinate", "joint"),
        )
    )
    return out


def _first(doc: dict, kind: str) -> str:
    return next(j["name"] for j in doc["joints"] if j["type"] == kind)


def _universal_parallel(doc: dict) -> dict:
    doc = copy.deepcopy(doc)
    for j in doc["joints"]:
        if j["type"] == "universal":
            j["axis2"] = list(j["axis"])
            break
    return doc


def _chain(n: int) -> dict:
    """A serial chain of ``n`` bodies on revolute joints, one motor per joint."""
    bodies = [{"name": "b0"}] + [{"name": f"b{i}"} for i in range(1, n)]
    joints = [
        {
            "name": f"j{i}",
            "type": "revolute",
            "bodies": [f"b{i - 1}", f"b{i}"],
            "anchor": [float(i), 0.0, 0.0],
            "axis": [0.0, 0.0, 1.0],
        }
        for i in range(1, n)
    ]
    return {
        "mechanism": {"name": f"chain{n}", "ground": "b0"},
        "bodies": bodies,
        "joints": joints,
        "motors": [{"name": f"m{i}", "joint": f"j{i}"} for i in range(1, n)],
        "outputs": [
            {"name": f"o{i}", "joint": f"j{i}", "min": -0.1, "max": 0.1}
            for i in range(1, n)
        ],
    }


# -- the cases ------------------------------------------------------------------------


def _run_with(rng: random.Random, doc: dict, out: str) -> tuple[str, list[str]]:
    """A command for a file mutated from ``doc`` (its motors and outputs give the
    values), drawn by ``rng``: mostly ``check``."""
    command = rng.choice(["check", "check", "check", "fk", "bk", "export"])
    extra = {
        "check": [],
        "fk": ["--motors", _motors_arg(doc)],
        "bk": ["--outputs", _outputs_arg(doc)],
        "export": ["--format", "mjcf", "--out", out],
    }[command]
    return command, [command, "{file}", *extra]


def file_cases(rng: random.Random) -> list[Case]:
    cases = []
    for name, b, doc, names in toml_mutations(rng):
        command, argv = _run_with(rng, base(b), "{tmp}/out.xml")
        valid = names and names[0] == "VALID"
        cases.append(
            Case(
                name=f"{b}: {name}",
                command=command,
                argv=argv,
                text=dumps(doc),
                expect=(0, 1, 2) if valid else (2,),
                names=tuple(n for n in names if n != "VALID"),
            )
        )
    # a body's stl file is <out>/<body>.stl: nothing may be written outside --out
    # ('..' makes '...stl' in it); a name with XML's special characters is escaped
    for name in ["../../evil", "a/b", "..", 'a<b&c"d']:
        doc = _renamed(base("four_bar"), "crank", name)
        fmt = "mjcf" if "<" in name else "stl"
        out = "{tmp}/a/b/out" + (".xml" if fmt == "mjcf" else "")
        cases.append(
            Case(
                f"four_bar: body named {name!r}, export {fmt}",
                "export",
                ["export", "{file}", "--format", fmt, "--out", out],
                dumps(doc),
                (0,) if name in ("..", 'a<b&c"d') else (2,),
                ("name",),
                extra={"inside": out},
            )
        )
    for fmt in ["mjcf", "stl"]:
        doc = _set(base("four_bar"), ("mechanism", "units"), "parsec")
        cases.append(
            Case(
                f"four_bar: units = 'parsec', export {fmt}",
                "export",
                ["export", "{file}", "--format", fmt, "--out", "{tmp}/o"],
                dumps(doc),
                (2,),
                ("units",),
            )
        )
    fb_text = (ROOT / BASES["four_bar"]).read_text()
    for name, text in [
        ("not TOML (prose)", "this is not a mechanism\n"),
        ("not TOML (JSON)", json.dumps(base("four_bar"))),
        ("TOML syntax error half-way", fb_text[: len(fb_text) // 2] + "\n[[joints\n"),
        ("truncated file", fb_text[: len(fb_text) // 3]),
        ("empty file", ""),
        ("only comments", "# nothing here\n"),
        ("binary file", bytes(range(256)) * 8),
        ("UTF-16 file", fb_text.encode("utf-16")),
        (
            "latin-1 bytes in a string",
            fb_text.replace("four-bar", "vier-gelenk\xe9").encode("latin-1"),
        ),
        ("NUL byte in the file", fb_text.replace("four-bar", "four\x00bar")),
        ("duplicated [mechanism] table", fb_text + "\n[mechanism]\nname = 'x'\n"),
        (
            "duplicated key",
            fb_text.replace('units = "mm"', 'units = "mm"\nunits = "m"'),
        ),
    ]:
        cases.append(Case(f"file: {name}", "check", ["check", "{file}"], text=text))
    for command, argv in [
        ("check", ["check", "{tmp}"]),
        ("check", ["check", "{tmp}/missing.toml"]),
        ("check", ["check", "/dev/null"]),
        ("check", ["check", ""]),
        ("fk", ["fk", "{tmp}/missing.toml", "--motors", "0"]),
        ("export", ["export", "{tmp}", "--format", "mjcf", "--out", "{tmp}/o.xml"]),
        ("check", ["check", "/proc/self/status"]),
    ]:
        cases.append(Case(f"path: {argv[1]}", command, argv, names=("",)))
    return cases


def cli_cases() -> list[Case]:
    fb, five, delta = (ROOT / BASES[b] for b in ("four_bar", "five_bar", "delta"))
    fbs, fives = str(fb), str(five)
    cases = []

    def add(command, argv, expect=(2,), names=(), timeout=TIMEOUT, text=None):
        label = " ".join(a.replace(str(ROOT) + "/", "") for a in argv)
        cases.append(Case(f"cli: {label}", command, argv, text, expect, names, timeout))

    bad_rows = [
        "",
        ",",
        "0.1,0.2",
        "nan",
        "inf",
        "-inf",
        "abc",
        "1e308",
        "0x10",
        "0.1;0.2",
        "0.1 0.2",
        "--",
        "[0.1]",
    ]
    for v in bad_rows:
        add("fk", ["fk", fbs, "--motors", v], names=("--motors",))
    # Python's float syntax (1_000) and an underflow to 0 with a trailing comma: read
    for v in ["1_000", "1e-400,"]:
        add("fk", ["fk", fbs, "--motors", v], expect=(0, 1, 2), names=("--motors",))
    for v in ["0.1", "nan,0", "1,2,3", "x,y", "1e308,1e308", " , "]:
        add("bk", ["bk", fives, "--outputs", v], names=("--outputs",))
    # far out of reach: documented exit 1 (the branch ends) or 2 (bounds)
    add("fk", ["fk", fbs, "--motors", "1000"], expect=(1, 2), names=("--motors",))
    add("bk", ["bk", fives, "--outputs", "0,500"], expect=(1, 2), names=("--outputs",))
    add("bk", ["bk", fives, "--outputs", "0,-1e6"], expect=(1, 2), names=("--outputs",))
    add("fk", ["fk", fbs], names=("--motors",))
    add("fk", ["fk", fbs, "--motors"], names=("--motors",))
    add(
        "fk",
        ["fk", fbs, "--motors", "0", "--max-rows", "0"],
        expect=(0, 2),
        names=("--max-rows",),
    )
    add(
        "fk",
        ["fk", fbs, "--motors", "0", "--max-rows", "-5"],
        expect=(0, 2),
        names=("--max-rows",),
    )
    add("fk", ["fk", fbs, "--motors", "0", "--max-rows", "abc"], names=("--max-rows",))
    for v in [
        "1,2",
        "nan,60,50",
        "a,b,c",
        "60,63,50,1",
        "1e308,63,50",
        "100,63,50",
        "",
        "{tmp}/missing.toml",
        "{tmp}",
        "{file}",
    ]:
        add(
            "fk",
            ["fk", fbs, "--motors", "0", "--design", v],
            names=("--design", "{file}"),
            text="[mechanism]\nname='x'\n" if v == "{file}" else None,
        )
    add(
        "fk",
        ["fk", fbs, "--motors", "0", "--design", fives],
        names=("--design", "parameters"),
    )
    # CSV files for --motors
    for label, text in [
        ("csv with text", "crank\nabc\n"),
        ("csv with NaN", "crank\nnan\n"),
        ("csv wrong header", "rocker\n0.1\n"),
        ("csv two columns", "0.1,0.2\n"),
        ("csv empty", ""),
        ("csv binary", bytes(range(256))),
        ("csv repeated header", "crank,crank\n0.1,0.1\n"),
    ]:
        cases.append(
            Case(
                f"cli: fk --motors <{label}>",
                "fk",
                ["fk", fbs, "--motors", "{file}"],
                text,
                names=("--motors", "{file}"),
            )
        )
    add("fk", ["fk", fbs, "--motors", "{tmp}"], names=("--motors",))
    add("fk", ["fk", fbs, "--motors", "0", "--bogus"], names=("--bogus",))
    add("check", ["check"], names=("file",))
    add("check", ["check", fbs, fbs], names=("unrecognized",))
    # export
    for argv, names in [
        (["--format", "obj", "--out", "{tmp}/a.obj"], ("--format",)),
        (["--format", "mjcf"], ("--out",)),
        (["--format", "mjcf", "--out", "/proc/nope/a.xml"], ("--out",)),
        (["--format", "mjcf", "--out", "/dev/null/a.xml"], ("--out",)),
        (["--format", "mjcf", "--out", "{tmp}"], ("--out",)),
        (["--format", "mjcf", "--out", ""], ("--out",)),
        (["--format", "stl", "--out", "{file}"], ("--out",)),
        (
            ["--format", "mjcf", "--out", "{tmp}/a.xml", "--thickness", "-1"],
            ("--thickness",),
        ),
        (
            ["--format", "mjcf", "--out", "{tmp}/a.xml", "--thickness", "nan"],
            ("--thickness",),
        ),
        (
            ["--format", "mjcf", "--out", "{tmp}/a.xml", "--thickness", "0"],
            ("--thickness",),
        ),
        (
            ["--format", "mjcf", "--out", "{tmp}/a.xml", "--thickness", "1e308"],
            ("--thickness",),
        ),
        (
            ["--format", "mjcf", "--out", "{tmp}/a.xml", "--thickness", "thick"],
            ("--thickness",),
        ),
        (["--format", "urdf", "--out", "{tmp}/a.urdf"], ("urdf", "URDF", "MJCF")),
        (
            ["--format", "glb", "--out", "{tmp}/a.glb", "--design", "nan,1,1"],
            ("--design",),
        ),
        (
            ["--format", "mjcf", "--out", "{tmp}/a.xml", "--design", "1,2"],
            ("--design",),
        ),
    ]:
        add(
            "export",
            ["export", fbs, *argv],
            names=names,
            text="x" if "{file}" in argv else None,
        )
    # plot (few: a plot that runs solves)
    for argv, names in [
        (["--out", "{tmp}/p", "--resolution", "0"], ("--resolution",)),
        (["--out", "{tmp}/p", "--resolution", "-3"], ("--resolution",)),
        (["--out", "{tmp}/p", "--resolution", "1000000"], ("--resolution", "cells")),
        (["--out", "{tmp}/p", "--resolution", "abc"], ("--resolution",)),
        (["--out", "{tmp}/p", "--max-cells", "0"], ("--max-cells", "cells")),
        (["--out", "{file}"], ("--out",)),
        (["--out", "/dev/null/p"], ("--out",)),
        (["--out", "{tmp}/p", "--label", "../../escape"], ("--label",)),
        (["--out", "{tmp}/p", "--label", ""], ("--label",)),
        (["--out", "{tmp}/p", "--design", "nan,1"], ("--design",)),
    ]:
        add(
            "plot",
            ["plot", fives, *argv],
            names=names,
            text="x" if "{file}" in argv else None,
        )
    # evaluate (a handful: compiling takes ~15 s)
    for argv, names in [
        (["--design", "nan,10,20"], ("--design",)),
        (["--design", "1,2"], ("--design",)),
        (["--design", "text"], ("--design",)),
        (["--design", "1000,1000,1000"], ("--design",)),
        (["--design", "{tmp}/missing.toml"], ("--design",)),
    ]:
        add(
            "evaluate",
            ["evaluate", fives, *argv],
            names=names,
            timeout=EVALUATE_TIMEOUT,
        )
    big = dumps(_set(base("five_bar"), ("evaluation", "samples_per_dimension"), 400))
    cases.append(
        Case(
            "cli: evaluate, 400 x 400 targets (over 10^5)",
            "evaluate",
            ["evaluate", "{file}"],
            big,
            (2,),
            ("samples",),
            EVALUATE_TIMEOUT,
        )
    )
    return cases


# -- running and classifying ----------------------------------------------------------

_ERROR = re.compile(r"^linkopt( [a-z ]+)?: error: ")


def classify(
    case: Case, rc: int | None, stdout: str, stderr: str, paths: dict | None = None
) -> tuple[str, str]:
    """(class, why) of one finished (or timed-out: ``rc`` None) run; ``paths`` gives
    what ``{file}`` and ``{tmp}`` in the names the message should give stand for."""
    if rc is None:
        return "hang", f"no answer within {case.timeout} s"
    if "Traceback (most recent call last)" in stdout + stderr:
        return "traceback", "a Python traceback"
    if rc == 3 or "internal error" in stderr:
        return "traceback", "internal error (exit 3)"
    if rc not in case.expect:
        return "wrong code", f"exit {rc}, expected {'/'.join(map(str, case.expect))}"
    if rc == 0:
        return "clean", "accepted (valid input)"
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    errors = [ln for ln in lines if _ERROR.match(ln)]
    if rc == 1 and len(errors) <= 1:
        return "clean", "exit 1: failed solve"
    if len(errors) != 1:
        return "unclear", f"{len(errors)} error lines on stderr"
    message = errors[0]
    wanted = [_fill(n, paths or {}) for n in case.names if n]
    if wanted and not any(n in message for n in wanted):
        return "unclear", f"message names none of {wanted}"
    return "clean", "one-line error"


def _fill(text: str, paths: dict) -> str:
    for key, value in paths.items():
        text = text.replace(key, value)
    return text


def run_case(case: Case, folder: Path, source: Path = ROOT) -> dict:
    folder.mkdir(parents=True, exist_ok=True)
    file = folder / "case.toml"
    if case.text is not None:
        mode = "wb" if isinstance(case.text, bytes) else "w"
        with open(file, mode) as f:
            f.write(case.text)
    paths = {"{file}": str(file), "{tmp}": str(folder)}
    argv = [_fill(a, paths) for a in case.argv]
    env = os.environ | {"PYTHONPATH": str(source)}
    env.setdefault("LINKOPT_CACHE_DIR", "/tmp/cache-campaign")
    start = time.monotonic()
    cmd = [sys.executable, "-m", "linkopt", *argv]
    try:
        proc = subprocess.run(
            cmd,
            cwd=source,
            env=env,
            capture_output=True,
            text=True,
            timeout=case.timeout,
            errors="replace",
        )
        rc, stdout, stderr = proc.returncode, proc.stdout, proc.stderr
    except subprocess.TimeoutExpired as err:
        rc, stdout, stderr = None, _text(err.stdout), _text(err.stderr)
    seconds = time.monotonic() - start
    kind, why = classify(case, rc, stdout, stderr, paths)
    if "inside" in case.extra:
        inside = Path(_fill(case.extra["inside"], paths))
        stray = [
            str(f.relative_to(folder))
            for f in folder.rglob("*")
            if f.is_file() and f != file and inside not in (f, *f.parents)
        ]
        if stray:
            kind, why = "wrong code", f"wrote outside --out: {stray}"
    record = {
        "case": case.name,
        "command": case.command,
        "argv": argv,
        "exit": rc,
        "class": kind,
        "why": why,
        "seconds": round(seconds, 2),
        "stderr": stderr.strip().splitlines()[-3:],
    }
    if kind == "traceback" and "--debug" not in argv:
        debug = subprocess.run(
            [sys.executable, "-m", "linkopt", "--debug", *argv],
            cwd=source,
            env=env,
            capture_output=True,
            text=True,
            timeout=case.timeout,
            errors="replace",
        )
        record["traceback"] = debug.stderr.strip().splitlines()[-6:]
    return record


def _text(b) -> str:
    if b is None:
        return ""
    return b.decode(errors="replace") if isinstance(b, bytes) else b


def all_cases(seed: int) -> list[Case]:
    rng = random.Random(seed)
    return file_cases(rng) + cli_cases()


def summary(records: list[dict]) -> dict:
    counts = {c: 0 for c in CLASSES}
    per_command: dict[str, dict[str, int]] = {}
    for r in records:
        counts[r["class"]] += 1
        row = per_command.setdefault(r["command"], {c: 0 for c in CLASSES})
        row[r["class"]] += 1
    return {"cases": len(records), **counts, "per_command": per_command}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--only", default="", help="run cases whose name has this")
    parser.add_argument("--list", action="store_true", help="list the cases")
    parser.add_argument("--no-write", action="store_true", help="write no JSON")
    parser.add_argument(
        "--source",
        type=Path,
        default=ROOT,
        help="the linkopt source tree to run (default: this checkout's), e.g. an "
        "export of an earlier commit, for the counts before a fix",
    )
    parser.add_argument("--label", default="", help="JSON file suffix, e.g. _before")
    args = parser.parse_args()
    cases = [c for c in all_cases(args.seed) if args.only in c.name]
    if args.list:
        for c in cases:
            print(f"{c.command:9s} {c.name}")
        print(len(cases), "cases")
        return
    records = []
    with tempfile.TemporaryDirectory(prefix="linkopt-campaign-") as tmp:
        for i, case in enumerate(cases):
            record = run_case(case, Path(tmp) / f"case{i:03d}", args.source)
            records.append(record)
            mark = "" if record["class"] == "clean" else f"  <- {record['class']}"
            print(
                f"[{i + 1}/{len(cases)}] {record['exit']} {record['seconds']:6.1f}s "
                f"{case.command:8s} {case.name}{mark}",
                flush=True,
            )
    report(records)
    if not args.no_write and not args.only:
        figures = {
            "seed": args.seed,
            "source": str(args.source),
            "summary": summary(records),
            "non_clean": [r for r in records if r["class"] != "clean"],
            "cases": [
                {k: r[k] for k in ("case", "command", "exit", "class", "seconds")}
                for r in records
            ],
        }
        script = __file__.replace(".py", f"{args.label}.py")
        print("wrote", _results.write(script, figures))


def report(records: list[dict]) -> None:
    s = summary(records)
    print("\n" + "  ".join(f"{k}: {s[k]}" for k in ("cases", *CLASSES)))
    for command, row in sorted(s["per_command"].items()):
        print(f"  {command:9s} " + "  ".join(f"{k} {v}" for k, v in row.items()))
    for r in records:
        if r["class"] != "clean":
            print(f"\n{r['class']}: {r['case']} (exit {r['exit']}: {r['why']})")
            for line in r.get("traceback", r["stderr"]):
                print("    " + line[:300])


if __name__ == "__main__":
    main()
