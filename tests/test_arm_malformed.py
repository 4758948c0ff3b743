"""Generated malformed input for the serial-arm readers and commands (hypothesis).

The shipped task files (``tasks/*.toml``) and task-point file are mutated: a value
replaced by another type, NaN, ±inf, a huge integer, a negative number, zero or 1e308;
a key deleted, an unknown key added, a key moved to another table. Each reader either
accepts the file or raises a :class:`~linkopt.LinkoptError` whose message is one line
naming the file. The ``linkopt arm`` commands get random flag values and must exit 0, 1
or 2, never 3; their work (the solves) is replaced by a stub, so a flag value that
reaches it must have been a valid one. Nothing here optimises.
"""

from __future__ import annotations

import copy
import json
import math
import tomllib
from pathlib import Path

import pytest
from hypothesis import given
from hypothesis import strategies as st

from linkopt import LinkoptError
from linkopt._arms.codesign.task import loads_task as load_arm_task
from linkopt._arms.dh.points import read_points
from linkopt._arms.trace.task import loads_task as load_trace_task
from linkopt._cli.main import main

ROOT = Path(__file__).resolve().parent.parent
TASKS = ROOT / "tasks"
ARM_TASKS = ("backpack_arm.toml", "elimination_square.toml")
TRACE_TASKS = ("rose.toml", "wipe_table.toml", "clean_table.toml")
POINTS = TASKS / "curve_cos5t_sin3t_sint.csv"


def _value(v) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, float) and math.isnan(v):
        return "nan"
    if isinstance(v, float) and math.isinf(v):
        return "inf" if v > 0 else "-inf"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, str):
        return json.dumps(v)
    if isinstance(v, list):
        return "[" + ", ".join(_value(x) for x in v) + "]"
    return (
        "{ " + ", ".join(f"{json.dumps(k)} = {_value(x)}" for k, x in v.items()) + " }"
    )


def _is_tables(v) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(data: dict) -> str:
    """TOML text of ``data``: top-level values, then tables, then arrays of tables."""
    lines = [
        f"{json.dumps(k)} = {_value(v)}"
        for k, v in data.items()
        if not isinstance(v, dict) and not _is_tables(v)
    ]
    for key, value in data.items():
        for table in [value] if isinstance(value, dict) else []:
            lines.append(f"[{json.dumps(key)}]")
            lines += [f"{json.dumps(k)} = {_value(v)}" for k, v in table.items()]
        for table in value if _is_tables(value) else []:
            lines.append(f"[[{json.dumps(key)}]]")
            lines += [f"{json.dumps(k)} = {_value(v)}" for k, v in table.items()]
    return "\n".join(lines) + "\n"


def _leaves(node, path=()):
    """Paths of every value that is not a table (entries of number lists included)."""
    if isinstance(node, dict):
        for k, v in node.items():
            yield from _leaves(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _leaves(v, path + (i,))
        yield path
    else:
        yield path


def _tables(node, path=()):
    if isinstance(node, dict):
        yield path
        for k, v in node.items():
            yield from _tables(v, path + (k,))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            yield from _tables(v, path + (i,))


def _at(node, path):
    for p in path:
        node = node[p]
    return node


BAD_VALUES = st.one_of(
    st.sampled_from(
        [
            float("nan"),
            float("inf"),
            float("-inf"),
            1e308,
            -1e308,
            2**63 - 1,
            -(2**63),
            -1,
            -0.5,
            0,
            0.0,
            "x",
            "",
            True,
            [],
            [1.0, 2.0],
            {"a": 1},
        ]
    ),
    st.floats(allow_nan=True, allow_infinity=True),
    st.integers(min_value=-(2**63), max_value=2**63 - 1),
)


@st.composite
def mutated(draw, data: dict) -> dict:
    """``data`` with one to three mutations (module docstring)."""
    data = copy.deepcopy(data)
    for _ in range(draw(st.integers(1, 3))):
        op = draw(st.sampled_from(["replace", "replace", "delete", "add", "move"]))
        tables = [p for p in _tables(data) if isinstance(_at(data, p), dict)]
        if op == "replace":
            path = draw(st.sampled_from([p for p in _leaves(data) if p]))
            _at(data, path[:-1])[path[-1]] = draw(BAD_VALUES)
        elif op == "delete":
            table = _at(data, draw(st.sampled_from(tables)))
            if table:
                del table[draw(st.sampled_from(sorted(table)))]
        elif op == "add":
            key = draw(st.sampled_from(["bogus", "voxel", "mass", "seed", "name"]))
            _at(data, draw(st.sampled_from(tables))).setdefault(key, 1.0)
        else:
            source = _at(data, draw(st.sampled_from(tables)))
            target = _at(data, draw(st.sampled_from(tables)))
            if source and source is not target:
                key = draw(st.sampled_from(sorted(source)))
                if key not in target and target is not source.get(key):
                    target[key] = source.pop(key)
    return data


def _parsed(name: str) -> dict:
    return tomllib.loads((TASKS / name).read_text(encoding="utf-8"))


ARM_DATA = {name: _parsed(name) for name in ARM_TASKS}
TRACE_DATA = {name: _parsed(name) for name in TRACE_TASKS}


def _accepts_or_one_line(load, text: str, source: str) -> None:
    try:
        load(text, source)
    except LinkoptError as err:
        message = str(err)
        assert message.startswith(f"{source}: ") and "\n" not in message, message


@given(st.sampled_from(ARM_TASKS).flatmap(lambda n: mutated(ARM_DATA[n])))
def test_mutated_arm_task_is_read_or_one_line(data):
    _accepts_or_one_line(load_arm_task, dumps(data), "mutated_arm.toml")


@given(st.sampled_from(TRACE_TASKS).flatmap(lambda n: mutated(TRACE_DATA[n])))
def test_mutated_trace_task_is_read_or_one_line(data):
    _accepts_or_one_line(load_trace_task, dumps(data), "mutated_trace.toml")


CELLS = st.one_of(
    st.sampled_from(["nan", "inf", "-inf", "1e308", "1e400", "abc", "", "1,2", "0x10"]),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers().map(str),
)


@given(
    st.lists(
        st.tuples(st.integers(0, 64), st.integers(0, 3), CELLS), min_size=1, max_size=3
    ),
    st.booleans(),
)
def test_mutated_points_file_is_read_or_one_line(tmp_path_factory, edits, drop):
    lines = POINTS.read_text(encoding="utf-8").splitlines()
    for row, column, cell in edits:
        cells = lines[row].split(",")
        cells[min(column, len(cells) - 1)] = cell
        lines[row] = ",".join(cells)
    if drop:
        lines = lines[:2]
    path = tmp_path_factory.mktemp("points") / "points.csv"
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    try:
        points = read_points(path)
    except LinkoptError as err:
        assert str(err).startswith(f"{path}: ") and "\n" not in str(err)
    else:
        assert points.shape[1] == 3 and abs(points).max() <= 1e6


class Reached(LinkoptError):
    """Raised by the stubbed solves: the command got past every check."""


@pytest.fixture
def no_work(monkeypatch):
    def stop(*args, **kwargs):
        raise Reached("reached the work")

    for target in (
        "linkopt._arms.codesign.nlp.prepare",
        "linkopt._arms.codesign.multistart.solve",
        "linkopt._cli.manipulability.synthesize_dh",
        "linkopt._arms.trace.synthesis.synthesize",
    ):
        monkeypatch.setattr(target, stop)


def _finite(text: str) -> float | None:
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None


def _integer(text: str) -> int | None:
    try:
        return int(text)
    except ValueError:
        return None


def _joints_valid(text: str) -> bool:
    if text.isdigit():
        return 1 <= int(text) <= 8
    return (
        0 < len(text) <= 12
        and set(text) <= {"R", "P"}
        and text.count("R") >= len(text) - 3
    )


def _in(low, high):
    return lambda text: (v := _integer(text)) is not None and low <= v <= high


#: Flag -> whether a value (as typed) is valid; every other flag keeps its default.
COMMANDS = {
    "design": (
        TASKS / "elimination_square.toml",
        {"--starts": _in(1, 1000), "--seed": _in(0, 2**64), "--workers": _in(1, 64)},
    ),
    "simplify": (
        TASKS / "elimination_square.toml",
        {"--starts": _in(1, 1000), "--min-joints": _in(1, 4)},
    ),
    "manipulability": (
        POINTS,
        {
            "--precision": lambda t: (v := _finite(t)) is not None and 0 < v <= 1e12,
            "--size-damping": lambda t: (
                (v := _finite(t)) is not None and 0 <= v <= 1e12
            ),
            "--starts": _in(1, 1000),
            "--iterations": _in(1, 1_000_000),
            "--joints": lambda t: _joints_valid(t.strip().upper()),
        },
    ),
    "trace": (
        TASKS / "wipe_table.toml",
        {
            "--restarts": _in(1, 1000),
            "--best-of": _in(1, 100),
            "--discretised": lambda t: (
                (v := _integer(t)) is not None and (v == 0 or 2 <= v <= 10_000)
            ),
            "--seed": _in(0, 2**64),
        },
    ),
}

FLAG_VALUES = st.one_of(
    st.sampled_from(["-1", "0", "nan", "inf", "-inf", "1e308", "abc", "", "0.5"]),
    st.integers(min_value=-(10**12), max_value=10**12).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.text(alphabet="RPrpX0123 ", max_size=12),
)


@given(data=st.data())
def test_random_arm_flags_exit_0_1_or_2_and_stop_before_work(
    data, no_work, tmp_path, capsys
):
    command = data.draw(st.sampled_from(sorted(COMMANDS)))
    source, flags = COMMANDS[command]
    flag = data.draw(st.sampled_from(sorted(flags)))
    value = data.draw(FLAG_VALUES)
    argv = ["arm", command, str(source), "--out", str(tmp_path / "out")]
    try:
        status = main([*argv, f"{flag}={value}"])
    except SystemExit as exit_:  # argparse: not a number at all
        status = exit_.code
    err = capsys.readouterr().err
    assert status in (0, 1, 2), err
    if "reached the work" in err:
        assert flags[flag](value), f"{flag}={value!r} was accepted"
    elif status == 2 and flags[flag](value):
        pytest.fail(f"{flag}={value!r} is valid but was refused: {err}")
