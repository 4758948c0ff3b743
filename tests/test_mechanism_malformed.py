"""Malformed mechanism files, generated: every shipped file, mutated (a value of another
type, NaN, inf, an integer too large for a float, an absurd magnitude, a deleted,
moved or unknown key, a duplicated name, a table where an array of tables belongs and
back), either loads or is one :class:`MechanismFileError` line naming the file; the CLI
exits 0 or 2, never 3. Below them, one regression test per kind of malformation.
"""

from __future__ import annotations

import copy
import json
import math
import re
import tomllib
from pathlib import Path

import pytest
from conftest import MECHANISMS
from hypothesis import given, settings
from hypothesis import strategies as st

import linkopt
from linkopt._cli.main import main
from linkopt._files.topology import MAX_BODIES

SHIPPED = sorted(MECHANISMS.glob("*.toml"))
PARSED = {path.stem: tomllib.loads(path.read_text()) for path in SHIPPED}

# --- a minimal TOML writer: every top-level key as one inline value -----------------


def toml_key(key: str) -> str:
    return key if re.fullmatch(r"[A-Za-z0-9_-]+", key) else json.dumps(key)


def toml_value(value) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        if math.isinf(value):
            return "inf" if value > 0 else "-inf"
        return repr(value)
    if isinstance(value, str):
        return json.dumps(value, ensure_ascii=False)
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    items = (f"{toml_key(k)} = {toml_value(v)}" for k, v in value.items())
    return "{" + ", ".join(items) + "}"


def toml_text(data: dict) -> str:
    """TOML text whose :func:`tomllib.loads` is ``data`` (inline tables only)."""
    return "".join(f"{toml_key(k)} = {toml_value(v)}\n" for k, v in data.items())


# --- mutations ----------------------------------------------------------------------

HUGE = 10**400
#: Values that are no valid field anywhere, or only by accident.
ODD_VALUES = [
    math.nan,
    math.inf,
    -math.inf,
    HUGE,
    -HUGE,
    1e308,
    -1e308,
    1e200,
    1e-300,
    0,
    -1,
    0.0,
    -2.5,
    2**63,
    True,
    "",
    "x",
    "revolute",
    "a\nb",
    [],
    [0],
    [math.nan, 0.0, 0.0],
    [math.inf, 0.0, 0.0],
    [1e308, 0.0, 0.0],
    [HUGE, 0, 0],
    [1e200, 1e200, 0.0],
    [1e-300, 0.0, 0.0],
    ["a", "b", "c"],
    [[1.0, 2.0, 3.0]],
    [1.0, "a", 2.0],
    {},
    {"x": 1.0},
    [{}],
    [{"name": "a"}],
]
#: Keys to add: unknown ones, and ones that belong to some other table.
KEYS = [
    "bogus",
    "Name",
    "a b",
    "x\ny",
    "name",
    "anchor",
    "axis",
    "axis2",
    "min",
    "max",
    "joint",
    "point",
    "body",
    "bodies",
    "coordinate",
    "angle",
    "mirror",
    "origin",
    "position",
    "normal",
    "reference_length",
    "tolerance",
    "alpha_factor",
    "joints",
]


def is_absurd(value) -> bool:
    if isinstance(value, bool) or isinstance(value, str):
        return False
    if isinstance(value, (int, float)):
        return not abs(value) < 1e100
    if isinstance(value, list):
        return any(is_absurd(v) for v in value)
    if isinstance(value, dict):
        return any(is_absurd(v) for v in value.values())
    return False


DIRECTIONS = ("axis", "axis2", "normal")


def has_absurd(data) -> bool:
    """Whether a number of ``data`` is non-finite or of magnitude 1e100 or more,
    leaving out directions (axes, the symmetry normal), whose length is free."""
    return any(
        is_absurd(container[key])
        and not isinstance(container[key], (list, dict))
        and not any(d in path for d in DIRECTIONS)
        for container, key, path in slots(data)
    )


def slots(data, path=()) -> list[tuple]:
    """``(container, key, path)`` of every value in the tree, tables and arrays
    included."""
    found = []
    items = data.items() if isinstance(data, dict) else enumerate(data)
    for key, value in items:
        found.append((data, key, path + (key,)))
        if isinstance(value, (dict, list)):
            found += slots(value, path + (key,))
    return found


def tables(data, path=()) -> list[tuple[dict, tuple]]:
    """Every table (dict) in the tree with its path, the top level included."""
    return [(data, path)] + [
        (value, p)
        for container, key, p in slots(data, path)
        if isinstance(value := container[key], dict)
    ]


def replace(draw, data: dict) -> str:
    container, key, path = draw(st.sampled_from(slots(data)))
    value = draw(st.sampled_from(ODD_VALUES))
    container[key] = copy.deepcopy(value)
    return f"replace {path} by {value!r}"


def scale(draw, data: dict) -> str:
    numbers = [
        s
        for s in slots(data)
        if isinstance(v := s[0][s[1]], (int, float)) and not isinstance(v, bool)
    ]
    if not numbers:
        return "scale: no number"
    container, key, path = draw(st.sampled_from(numbers))
    factor = draw(st.sampled_from([1e300, 1e-300, -1.0, 1e6, 1e-6]))
    container[key] = container[key] * factor
    return f"scale {path} by {factor}"


def delete(draw, data: dict) -> str:
    keyed = [s for s in slots(data) if isinstance(s[0], dict)]
    container, key, path = draw(st.sampled_from(keyed))
    del container[key]
    return f"delete {path}"


def move(draw, data: dict) -> str:
    keyed = [s for s in slots(data) if isinstance(s[0], dict)]
    container, key, path = draw(st.sampled_from(keyed))
    value = container.pop(key)
    target, where = draw(st.sampled_from(tables(data)))
    target[key] = value
    return f"move {path} into {where}"


def add_key(draw, data: dict) -> str:
    target, where = draw(st.sampled_from(tables(data)))
    key = draw(st.sampled_from(KEYS))
    value = draw(st.sampled_from(ODD_VALUES + [{"bogus": 1}, "ground"]))
    target[key] = copy.deepcopy(value)
    return f"add {key!r} = {value!r} to {where}"


def duplicate(draw, data: dict) -> str:
    arrays = [
        k
        for k, v in data.items()
        if isinstance(v, list) and v and all(isinstance(e, dict) for e in v)
    ]
    if not arrays:
        return "duplicate: no array"
    key = draw(st.sampled_from(arrays))
    entries = data[key]
    k = draw(st.integers(0, len(entries) - 1))
    if len(entries) > 1 and draw(st.booleans()):
        other = (k + 1) % len(entries)
        entries[other]["name"] = entries[k].get("name")
        return f"rename {key}[{other}] as {key}[{k}]"
    entries.append(copy.deepcopy(entries[k]))
    return f"append a copy of {key}[{k}]"


def swap_shape(draw, data: dict) -> str:
    """A table where an array of tables belongs, and back."""
    key = draw(st.sampled_from(sorted(data)))
    value = data[key]
    if isinstance(value, dict):
        data[key] = [value]
    elif isinstance(value, list) and value:
        data[key] = value[0]
    else:
        data[key] = {}
    return f"swap the shape of {key}"


MUTATIONS = [replace, replace, scale, delete, move, add_key, duplicate, swap_shape]


@st.composite
def mutated_files(draw, steps: int = 2) -> tuple[str, dict, list[str], bool]:
    """``(stem, data, what was done, whether it holds an absurd value)``."""
    stem = draw(st.sampled_from(sorted(PARSED)))
    data = copy.deepcopy(PARSED[stem])
    done = []
    for _ in range(draw(st.integers(1, steps))):
        if not data:
            break
        done.append(draw(st.sampled_from(MUTATIONS))(draw, data))
    return stem, data, done, has_absurd(data)


def write(tmp: Path, stem: str, data: dict) -> Path:
    path = tmp / f"{stem}.toml"
    path.write_text(toml_text(data), encoding="utf-8")
    return path


def misleading(message: str) -> bool:
    return "mobility" in message or "singularity" in message


# --- generated inputs ---------------------------------------------------------------


def test_the_writer_round_trips_every_shipped_file():
    for data in PARSED.values():
        assert tomllib.loads(toml_text(data)) == data


@settings(max_examples=80)
@given(case=mutated_files())
def test_a_mutated_file_loads_or_is_one_error_line(case, tmp_path_factory):
    stem, data, done, absurd = case
    path = write(tmp_path_factory.mktemp("mutated"), stem, data)
    try:
        linkopt.load(path)
    except linkopt.MechanismFileError as err:
        text = str(err)
        assert text.startswith(f"{path}: ") and "\n" not in text, (done, text)
        assert not (absurd and misleading(text)), (done, text)
    else:
        assert not absurd, done


@settings(max_examples=30)
@given(case=mutated_files())
def test_check_on_a_mutated_file_exits_0_or_2_with_one_line(
    case, tmp_path_factory, capsys
):
    stem, data, done, _ = case
    path = write(tmp_path_factory.mktemp("mutated"), stem, data)
    capsys.readouterr()
    code = main(["check", str(path)])
    err = capsys.readouterr().err.strip()
    assert code in (0, 2), (done, err)
    if code == 2:
        assert err.count("\n") == 0 and err.startswith(f"linkopt: error: {path}: ")


# --- regressions, one per kind ------------------------------------------------------


def five_bar(edit) -> dict:
    data = copy.deepcopy(PARSED["five_bar"])
    edit(data)
    return data


def neck(edit) -> dict:
    data = copy.deepcopy(PARSED["neck_2dof"])
    edit(data)
    return data


def put(path: tuple, value):
    """An edit that sets the value at ``path`` (keys and indices) of a parsed file."""

    def edit(data):
        for key in path[:-1]:
            data = data[key]
        data[path[-1]] = value

    return edit


def shift_anchors(offset: float):
    def edit(data):
        for joint in data["joints"]:
            joint["anchor"][1] += offset

    return edit


#: name -> (parsed file, the field the error names, words of the message).
MALFORMED = {
    # a field of the wrong TOML type, in every table
    "mechanism_a_number": (
        five_bar(put(("mechanism",), 5)),
        "[mechanism]",
        "expected a table, got 5",
    ),
    "mechanism_an_array_of_tables": (
        five_bar(put(("mechanism",), [PARSED["five_bar"]["mechanism"]])),
        "[mechanism]",
        "expected a table, got [{",
    ),
    "name_a_list": (
        five_bar(put(("mechanism", "name"), ["five-bar"])),
        "[mechanism].name",
        "expected a non-empty string",
    ),
    "units_a_number": (
        five_bar(put(("mechanism", "units"), 5)),
        "[mechanism].units",
        "expected a non-empty string, got 5",
    ),
    "symmetry_a_number": (
        five_bar(put(("symmetry",), 3)),
        "[symmetry]",
        "expected a table, got 3",
    ),
    "symmetry_an_array_of_tables": (
        five_bar(put(("symmetry",), [PARSED["five_bar"]["symmetry"]])),
        "[symmetry]",
        "expected a table",
    ),
    "solver_a_string": (
        five_bar(put(("solver",), "fast")),
        "[solver]",
        "expected a table, got 'fast'",
    ),
    "evaluation_a_list": (
        five_bar(put(("evaluation",), [1, 2])),
        "[evaluation]",
        "expected a table, got [1, 2]",
    ),
    "parameters_a_table": (
        five_bar(put(("parameters",), PARSED["five_bar"]["parameters"][0])),
        "[[parameters]]",
        "expected an array of tables ([[parameters]]), got {",
    ),
    "motors_a_number": (
        five_bar(put(("motors",), 5)),
        "[[motors]]",
        "expected an array of tables",
    ),
    "outputs_numbers": (
        five_bar(put(("outputs",), [1, 2])),
        "[[outputs]]",
        "expected an array of tables",
    ),
    "points_a_string": (
        five_bar(put(("points",), "ee")),
        "[[points]]",
        "expected an array of tables",
    ),
    "bodies_a_string": (
        five_bar(put(("joints", 0, "bodies"), "ground")),
        "joints[0].bodies",
        "expected a list of two body names",
    ),
    "parameter_joint_a_table": (
        five_bar(put(("parameters", 0, "joint"), {"x": 1})),
        "parameters[0].joint",
        "unknown joint {'x': 1}",
    ),
    "max_iterations_a_float": (
        five_bar(put(("solver",), {"max_iterations": 2.5})),
        "[solver].max_iterations",
        "expected an integer, got 2.5",
    ),
    "interior_a_number": (
        five_bar(put(("evaluation", "interior"), 1)),
        "[evaluation].interior",
        "expected true or false, got 1",
    ),
    "ik_iterations_a_string": (
        five_bar(put(("evaluation", "ik_iterations"), "40")),
        "[evaluation].ik_iterations",
        "expected an integer, got '40'",
    ),
    "angle_a_float": (
        neck(put(("outputs", 0, "angle"), 1.0)),
        "outputs[0].angle",
        "expected an integer, got 1.0",
    ),
    "targets_a_number": (
        five_bar(put(("evaluation", "targets"), 5)),
        "[evaluation].targets",
        "expected a list of at most 100000 targets, got 5",
    ),
    "target_of_the_wrong_size": (
        five_bar(put(("evaluation", "targets"), [[0.0, 40.0], [1.0]])),
        "[evaluation].targets[1]",
        "expected a list of 2 finite numbers (one per output), got [1.0]",
    ),
    "target_outside_the_range": (
        five_bar(put(("evaluation", "targets"), [[0.0, 40.0], [0.0, 90.0]])),
        "[evaluation].targets[1]",
        "expected a target inside the output range: y in [15, 80], got 90",
    ),
    # integers too large for a float
    "huge_int_anchor": (
        five_bar(put(("joints", 0, "anchor"), [HUGE, 0, 0])),
        "joints[0].anchor",
        "expected a list of 3 finite numbers, got [1000000",
    ),
    "huge_int_reference_length": (
        five_bar(put(("mechanism", "reference_length"), HUGE)),
        "[mechanism].reference_length",
        "expected a finite number",
    ),
    "huge_int_output_min": (
        five_bar(put(("outputs", 0, "min"), -HUGE)),
        "outputs[0].min",
        "expected a finite number",
    ),
    "huge_int_max_iterations": (
        five_bar(put(("solver",), {"max_iterations": HUGE})),
        "[solver].max_iterations",
        "expected an integer from 1 to 10000",
    ),
    "huge_int_samples": (
        five_bar(put(("evaluation", "samples_per_dimension"), HUGE)),
        "[evaluation].samples_per_dimension",
        "expected an integer from 2 to 100",
    ),
    # NaN, inf and absurd magnitudes, named before any solving
    "reference_length_1e308": (
        five_bar(put(("mechanism", "reference_length"), 1e308)),
        "[mechanism].reference_length",
        "expected a number from 1e-12 to 1e+12, got 1e+308",
    ),
    "reference_length_1e-300": (
        five_bar(put(("mechanism", "reference_length"), 1e-300)),
        "[mechanism].reference_length",
        "expected a number from 1e-12 to 1e+12, got 1e-300",
    ),
    "reference_length_far_from_the_span": (
        five_bar(put(("mechanism", "reference_length"), 1e9)),
        "[mechanism].reference_length",
        "1e+09 is not within a factor 1000 of the span of the joint anchors (74)",
    ),
    "reference_length_nan": (
        five_bar(put(("mechanism", "reference_length"), math.nan)),
        "[mechanism].reference_length",
        "expected a finite number, got nan",
    ),
    "anchor_1e308": (
        five_bar(put(("joints", 4, "anchor"), [0.0, 1e308, 0.0])),
        "joints[4].anchor",
        "expected coordinates of magnitude at most 1e+12 file units, got 1e+308",
    ),
    "anchors_far_from_the_origin": (
        five_bar(shift_anchors(1e10)),
        "joints[0].anchor",
        "at most 7.4e+07 file units (1e+06 reference lengths of 74",
    ),
    "anchor_inf": (
        five_bar(put(("joints", 0, "anchor"), [math.inf, 0.0, 0.0])),
        "joints[0].anchor",
        "expected a list of 3 finite numbers, got [inf, 0.0, 0.0]",
    ),
    "axis_nan": (
        five_bar(put(("joints", 0, "axis"), [math.nan, 0.0, 1.0])),
        "joints[0].axis",
        "expected a list of 3 finite numbers",
    ),
    "axis_underflowing": (
        five_bar(put(("joints", 0, "axis"), [1e-300, 0.0, 0.0])),
        "joints[0].axis",
        "zero-length axis",
    ),
    "origin_1e300": (
        five_bar(put(("bodies", 1, "origin"), [1e300, 0.0, 0.0])),
        "bodies[1].origin",
        "expected coordinates of magnitude at most 7.4e+07 file units",
    ),
    "point_position_1e200": (
        five_bar(
            put(
                ("points", 0),
                {"name": "ee", "body": "ground", "position": [0.0, 1e200, 0.0]},
            )
        ),
        "points[0].position",
        "expected coordinates of magnitude at most",
    ),
    "symmetry_point_inf": (
        five_bar(put(("symmetry", "point"), [0.0, -math.inf, 0.0])),
        "[symmetry].point",
        "expected a list of 3 finite numbers",
    ),
    "symmetry_point_1e300": (
        five_bar(put(("symmetry", "point"), [0.0, 1e300, 0.0])),
        "[symmetry].point",
        "expected coordinates of magnitude at most",
    ),
    "output_min_nan": (
        five_bar(put(("outputs", 0, "min"), math.nan)),
        "outputs[0].min",
        "expected a finite number, got nan",
    ),
    "output_max_inf": (
        five_bar(put(("outputs", 1, "max"), math.inf)),
        "outputs[1].max",
        "expected a finite number, got inf",
    ),
    "output_range_1e300": (
        five_bar(put(("outputs", 0, "min"), -1e300)),
        "outputs[0].min",
        "expected coordinates of magnitude at most 7.4e+07 file units",
    ),
    "output_max_1e300": (
        five_bar(put(("outputs", 1, "max"), 1e300)),
        "outputs[1].max",
        "expected coordinates of magnitude at most 7.4e+07 file units",
    ),
    "output_min_above_max": (
        five_bar(put(("outputs", 0, "min"), 50.0)),
        "outputs[0].min",
        "target range needs min < max, got min=50.0 and max=40.0",
    ),
    # the end of the range that is out of bounds is the one named (it was always min)
    "angle_range_1e5": (
        neck(put(("outputs", 0, "max"), 1e5)),
        "outputs[0].max",
        "expected angles of magnitude at most 1000 rad, got 100000",
    ),
    # the bound that is out of range is the one named (it was always min)
    "parameter_bound_1e300": (
        five_bar(put(("parameters", 0, "max"), 1e300)),
        "parameters[0].max",
        "expected coordinates of magnitude at most 7.4e+07 file units",
    ),
    "parameter_rest_above_max": (
        five_bar(put(("parameters", 0, "max"), 15.0)),
        "parameters[0].max",
        "the rest value 20 of base_right.x lies outside [5, 15]",
    ),
    "parameter_rest_below_min": (
        five_bar(put(("parameters", 0, "min"), 25.0)),
        "parameters[0].min",
        "the rest value 20 of base_right.x lies outside [25, 45]",
    ),
    "parameter_min_above_max": (
        five_bar(put(("parameters", 0, "min"), 90.0)),
        "parameters[0].min",
        "bounds need min < max",
    ),
    "tolerance_1e-300": (
        five_bar(put(("solver",), {"tolerance": 1e-300})),
        "[solver].tolerance",
        "expected a number from 1e-16 to 0.01, got 1e-300",
    ),
    "damping_1e300": (
        five_bar(put(("solver",), {"initial_damping": 1e300})),
        "[solver].initial_damping",
        "expected a number from 1e-16 to 1e+06",
    ),
    "max_step_1e3": (
        five_bar(put(("evaluation", "max_step"), 1e3)),
        "[evaluation].max_step",
        "expected a number from 1e-09 to 10, got 1000.0",
    ),
    "alpha_factor_negative": (
        five_bar(put(("evaluation", "alpha_factor"), -3.0)),
        "[evaluation].alpha_factor",
        "expected a number from 1e-06 to 1e+06, got -3.0",
    ),
    "target_inf": (
        five_bar(put(("evaluation", "targets"), [[0.0, math.inf]])),
        "[evaluation].targets[0]",
        "expected a list of 2 finite numbers",
    ),
    "target_far_away": (
        five_bar(put(("evaluation", "targets"), [[0.0, 1e300]])),
        "[evaluation].targets[0]",
        "expected coordinates of magnitude at most",
    ),
    # misplaced, unknown and oddly spelled keys
    "key_with_a_newline": (
        five_bar(put(("joints", 0, "a\nb"), 1)),
        "joints[0].'a\\nb'",
        "unknown field",
    ),
    "nested_table_in_mechanism": (
        five_bar(put(("mechanism", "extra"), {"x": 1})),
        "[mechanism].extra",
        "unknown field; expected one of ['ground', 'name', 'reference_length', "
        "'units']",
    ),
    "top_level_key": (
        five_bar(put(("name",), "five-bar")),
        "name",
        "unknown table",
    ),
}
#: 10 000 targets are within MAX_TARGETS; 3 outputs at 100 per output are not.
MALFORMED["too_many_targets"] = (
    {
        **PARSED["neck_3dof"],
        "evaluation": {"samples_per_dimension": 100},
    },
    "[evaluation].samples_per_dimension",
    "100 per output for 3 outputs makes 1000000 targets; expected at most 100000",
)

#: Where each table of the five-bar is, and a key that belongs to another table.
TABLES = {
    "[mechanism]": (("mechanism",), "anchor"),
    "bodies[1]": (("bodies", 1), "joint"),
    "joints[2]": (("joints", 2), "min"),
    "motors[0]": (("motors", 0), "axis"),
    "points[0]": (("points", 0), "coordinate"),
    "outputs[1]": (("outputs", 1), "body"),
    "[symmetry]": (("symmetry",), "mirror"),
    "parameters[2]": (("parameters", 2), "normal"),
    "[solver]": (("solver",), "alpha_factor"),
    "[evaluation]": (("evaluation",), "tolerance"),
}
for where, (path, key) in TABLES.items():
    MALFORMED[f"misplaced_{key}_in_{path[0]}"] = (
        five_bar(
            put((*path, key), 1.0) if path != ("solver",) else put(path, {key: 1.0})
        ),
        f"{where}.{key}",
        "unknown field; expected one of [",
    )
    MALFORMED[f"unknown_table_in_{path[0]}"] = (
        five_bar(
            put((*path, "extra"), {"name": "x"})
            if path != ("solver",)
            else put(path, {"extra": {}})
        ),
        f"{where}.extra",
        "unknown field; expected one of [",
    )


@pytest.mark.parametrize("name", sorted(MALFORMED))
def test_a_malformed_file_names_its_field(name, tmp_path, capsys):
    data, where, words = MALFORMED[name]
    path = write(tmp_path, name, data)
    with pytest.raises(linkopt.MechanismFileError) as info:
        linkopt.load(path)
    text = str(info.value)
    assert text.startswith(f"{path}: {where}: ") and words in text, text
    assert "\n" not in text and not misleading(text)
    assert main(["check", str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err == f"linkopt: error: {text}"


@pytest.mark.parametrize(
    "edit",
    [
        put(("joints", 0, "axis"), [0.0, 0.0, 1e200]),
        put(("joints", 1, "axis"), [0.0, 1e-200, 1e308]),
        put(("symmetry", "normal"), [1e300, 0.0, 0.0]),
    ],
    ids=["1e200", "1e308", "normal"],
)
def test_a_huge_direction_is_that_direction(edit, tmp_path):
    """An axis is a direction: its length may overflow a float, it is scaled first."""
    mech = linkopt.load(write(tmp_path, "five_bar", five_bar(edit)))
    reference = linkopt.load(MECHANISMS / "five_bar.toml")
    assert (mech.axes == reference.axes).all()
    assert (mech.symmetry.direction == reference.symmetry.direction).all()


def test_evaluation_targets_are_read(tmp_path):
    data = five_bar(put(("evaluation", "targets"), [[0.0, 40.0], [10, 20.5]]))
    mech = linkopt.load(write(tmp_path, "five_bar", data))
    assert mech.evaluation.targets == ((0.0, 40.0), (10.0, 20.5))


def serial_chain(count: int, island: bool = False) -> str:
    """A planar chain of ``count`` revolute joints (``count + 1`` bodies), one motor
    and one angle output each; ``island`` adds two bodies joined to each other only."""
    lines = ['[mechanism]\nname = "chain"\nground = "b0"\n']
    lines += [f'[[bodies]]\nname = "b{k}"\n' for k in range(count + 1)]
    lines += [
        f'[[joints]]\nname = "j{k}"\ntype = "revolute"\nbodies = ["b{k}", "b{k + 1}"]\n'
        f"anchor = [{10.0 * k}, 0.0, 0.0]\naxis = [0.0, 0.0, 1.0]\n"
        for k in range(count)
    ]
    if island:
        lines += ['[[bodies]]\nname = "i0"\n[[bodies]]\nname = "i1"\n']
        lines += [
            '[[joints]]\nname = "ij"\ntype = "revolute"\nbodies = ["i0", "i1"]\n'
            "anchor = [0.0, 5.0, 0.0]\naxis = [0.0, 0.0, 1.0]\n"
        ]
    lines += [f'[[motors]]\nname = "m{k}"\njoint = "j{k}"\n' for k in range(count)]
    lines += [
        f'[[outputs]]\nname = "o{k}"\njoint = "j{k}"\nmin = -0.1\nmax = 0.1\n'
        for k in range(count)
    ]
    return "\n".join(lines)


@pytest.mark.parametrize("count, island", [(MAX_BODIES, False), (9999, True)])
def test_a_mechanism_too_large_is_refused_before_work(count, island, monkeypatch):
    """Regression: a 1,000-body chain ran past 300 s and a 10,000-body one past 6 GB
    (before the banded solves and load-time checks). A file of more than
    ``MAX_BODIES`` bodies is refused while reading, with its count and the limit,
    before any solve."""
    from linkopt._engine import programs

    def no_work(*args, **kwargs):
        raise AssertionError("a program ran for a mechanism that should be refused")

    monkeypatch.setattr(programs, "call", no_work)
    with pytest.raises(linkopt.MechanismFileError) as error:
        linkopt.loads(serial_chain(count, island), "chain.toml")
    message = str(error.value)
    bodies = count + 1 + 2 * island
    assert "chain.toml: [[bodies]]" in message and f"{bodies} bodies" in message
    assert f"at most {MAX_BODIES} bodies" in message and "\n" not in message


def test_a_grid_of_many_outputs_is_counted_in_a_line():
    """A grid of 3 samples per output for 1,000 outputs (a chain of 1,000 motors) is
    named by its size, not its 478 digits."""
    with pytest.raises(linkopt.MechanismFileError) as error:
        linkopt.loads(serial_chain(1000), "chain.toml")
    message = str(error.value)
    assert "3 per output for 1000 outputs makes about 1.3e477 targets" in message
    assert len(message) < 200
