"""Arm task files (TOML): the arm's modules, targets, obstacles, gravity, weights.

Format (lengths in metres, masses in kg, angles in radians unless named ``..._deg``)::

    [task]
    name = "backpack arm"
    gravity = [0.0, 0.0, -9.81]
    torque_limit = 9.0        # τ_max of eq. 7 (N·m), every actuator
    module_radius = 0.04      # collision radius of the modules
    payload = 0.0             # optional, kg at the tool tip

    [[modules]]               # base first, tool last, at least one joint
    type = "base"             # base | joint | link | segment | tool (see _arm_model)
    z = { min = 0.0, max = 0.3, init = 0.1 }   # a design variable (init: optional)
    yaw = 0.5                                    # a fixed value; omitted slots are 0
    [[modules]]
    type = "link"
    length = { min = 0.1, max = 0.6 }           # required for link and tool
    mass = 0.2                                   # required for joint, link and tool

    [[targets]]               # in the order they are visited
    position = [0.4, 0.0, 0.6]
    axis = [0.0, 0.0, 1.0]    # optional tip axis (eq. 3)
    # orientation = [[1,0,0],[0,1,0],[0,0,1]]  # optional orientation (eq. 4), rows
    # approach = { local = [1,0,0], direction = [0,0,-1], angle_deg = 30 }  # tool axis
    #   ``local`` within ``angle_deg`` of the world ``direction`` (Sec. III-E)

    [[obstacles]]             # box {center, size, orientation?}
    type = "box"              # | sphere {center, radius} | capsule {a, b, radius}
    #                         # | mesh {path, center?, scale?}
    #   a box's orientation: rotation matrix (rows), its columns the edge directions

    [workspace]               # required with obstacles: the voxel grid of the SDF
    lower = [-1, -1, -1]
    upper = [1, 1, 1]
    voxel = 0.02              # optional (paper: 2 cm)
    clearance = 0.05          # optional ε of the CHOMP cost, default 2 voxels

Optional tables with the paper's defaults: ``[weights]`` path 500, joints 200, length 1,
torque 20, obstacle 5000; ``[tolerances]`` position 5e-4, tip 1e-3, rotation 1e-2;
``[solver]`` starts 8, seed 0, max_iterations 300, waypoints_per_target 4.
Every problem raises one :class:`~linkopt.MechanismFileError` naming file and field.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from jaxtyping import Float

from ..._engine.fields import Reader, is_number_list, parse_text, parse_toml
from .model import LENGTH_SLOTS, SLOTS, Arm, Module, make_arm
from .sdf import Obstacle, load_mesh

TOP_LEVEL = {
    "task",
    "modules",
    "targets",
    "obstacles",
    "workspace",
    "weights",
    "tolerances",
    "solver",
}
WEIGHTS = {
    "path": 500.0,
    "joints": 200.0,
    "length": 1.0,
    "torque": 20.0,
    "obstacle": 5000.0,
}
TOLERANCES = {"position": 5e-4, "tip": 1e-3, "rotation": 1e-2}
SOLVER = {"starts": 8, "seed": 0, "max_iterations": 300, "waypoints_per_target": 4}
OBSTACLE_FIELDS = {
    "box": ({"center", "size"}, {"orientation"}),
    "sphere": ({"center", "radius"}, set()),
    "capsule": ({"a", "b", "radius"}, set()),
    "mesh": ({"path"}, {"center", "scale"}),
}


@dataclass(frozen=True)
class Target:
    """A target pose: position, optional tip axis / orientation / approach cone."""

    position: np.ndarray  # (3,)
    axis: np.ndarray | None = None  # (3,) unit
    orientation: np.ndarray | None = None  # (3, 3)
    # (local axis, world direction, cos(angle))
    approach: tuple[np.ndarray, np.ndarray, float] | None = None


@dataclass(frozen=True, eq=False)
class Task:
    """A parsed, validated arm task (hashed by identity)."""

    name: str
    source: str
    arm: Arm
    targets: tuple[Target, ...]
    obstacles: tuple[Obstacle, ...]
    gravity: np.ndarray
    payload: float
    weights: dict = field(default_factory=lambda: dict(WEIGHTS))
    tolerances: dict = field(default_factory=lambda: dict(TOLERANCES))
    solver: dict = field(default_factory=lambda: dict(SOLVER))
    workspace: tuple[np.ndarray, np.ndarray] | None = None
    voxel: float = 0.02
    clearance: float = 0.04


def _slot(
    rd: Reader,
    item: dict,
    slot: str,
    where: str,
    names: list,
    bounds: list,
    required: bool,
):
    """One module slot: a fixed number, or ``{min, max, init?}`` (a design variable)."""
    if slot not in item:
        if required:
            raise rd.fail(f"{where}.{slot}", "missing required field")
        return (-1, 0.0)
    value = item[slot]
    if isinstance(value, dict):
        rd.keys(value, f"{where}.{slot}", {"min", "max", "init"}, {"min", "max"})
        low, high = (
            rd.number(value, "min", f"{where}.{slot}"),
            rd.number(value, "max", f"{where}.{slot}"),
        )
        if low >= high:
            raise rd.fail(
                f"{where}.{slot}", f"needs min < max, got min={low} and max={high}"
            )
        init = (
            rd.number(value, "init", f"{where}.{slot}")
            if "init" in value
            else 0.5 * (low + high)
        )
        if not low <= init <= high:
            raise rd.fail(f"{where}.{slot}.init", f"{init} is outside [{low}, {high}]")
        names.append(f"{item.get('name', where)}.{slot}")
        bounds.append((init, low, high, slot in LENGTH_SLOTS))
        return (len(names) - 1, init)
    return (-1, rd.number(item, slot, where))


def _read_modules(rd: Reader, data: dict) -> tuple[tuple[Module, ...], list, list]:
    items = rd.entries(data, "modules", required=True)
    modules, names, bounds = [], [], []
    for k, item in enumerate(items):
        where = f"modules[{k}]"
        kind = item.get("type")
        if not isinstance(kind, str) or kind not in SLOTS:
            raise rd.fail(
                f"{where}.type",
                f"unknown module type {kind!r}; expected one of {list(SLOTS)}",
            )
        needs_mass = kind in ("joint", "link", "tool")
        rd.keys(
            item,
            where,
            {"type", "name", "mass", *SLOTS[kind]},
            {"type"} | ({"mass"} if needs_mass else set()),
        )
        mass = rd.number(item, "mass", where) if "mass" in item else 0.0
        if mass < 0:
            raise rd.fail(f"{where}.mass", f"expected a mass >= 0, got {mass}")
        slots = tuple(
            _slot(rd, item, s, where, names, bounds, s == "length") for s in SLOTS[kind]
        )
        modules.append(Module(kind, slots, mass))
    kinds = [m.kind for m in modules]
    if kinds[0] != "base" or kinds.count("base") != 1:
        raise rd.fail(
            "modules[0].type", "the first module, and only it, must be the 'base'"
        )
    if kinds[-1] != "tool" or kinds.count("tool") != 1:
        raise rd.fail(
            f"modules[{len(kinds) - 1}].type",
            "the last module, and only it, must be the 'tool'",
        )
    if "joint" not in kinds:
        raise rd.fail("[[modules]]", "an arm needs at least one 'joint' module")
    return tuple(modules), names, bounds


def _read_orientation(rd: Reader, value, where: str) -> Float[np.ndarray, "3 3"]:
    """A rotation matrix given as its three rows."""
    ok = (
        isinstance(value, list)
        and len(value) == 3
        and all(is_number_list(r, 3) for r in value)
    )
    matrix = np.asarray(value, dtype=float) if ok else None
    if (
        matrix is None
        or np.abs(matrix @ matrix.T - np.eye(3)).max() > 1e-6
        or np.linalg.det(matrix) < 0
    ):
        raise rd.fail(
            where, "expected a 3x3 rotation matrix (rows, orthonormal, det +1)"
        )
    return matrix


def _read_targets(rd: Reader, data: dict) -> tuple[Target, ...]:
    targets = []
    for k, item in enumerate(rd.entries(data, "targets", required=True)):
        where = f"targets[{k}]"
        rd.keys(
            item,
            where,
            {"position", "axis", "orientation", "approach"},
            {"position"},
        )
        axis = rd.direction(item, "axis", where) if "axis" in item else None
        orientation = (
            _read_orientation(rd, item["orientation"], f"{where}.orientation")
            if "orientation" in item
            else None
        )
        approach = (
            _read_approach(rd, item["approach"], f"{where}.approach")
            if "approach" in item
            else None
        )
        targets.append(
            Target(rd.vector(item, "position", where), axis, orientation, approach)
        )
    return tuple(targets)


def _read_approach(
    rd: Reader, cone, where: str
) -> tuple[Float[np.ndarray, " 3"], Float[np.ndarray, " 3"], float]:
    """The approach cone ``(local axis, world direction, cos(angle))``."""
    if not isinstance(cone, dict):
        raise rd.fail(where, "expected a table {local, direction, angle_deg}")
    rd.keys(
        cone,
        where,
        {"local", "direction", "angle_deg"},
        {"local", "direction", "angle_deg"},
    )
    angle = rd.positive(cone, "angle_deg", where)
    return (
        rd.direction(cone, "local", where),
        rd.direction(cone, "direction", where),
        math.cos(math.radians(angle)),
    )


def _read_obstacles(rd: Reader, data: dict, base: Path) -> tuple[Obstacle, ...]:
    obstacles = []
    for k, item in enumerate(rd.entries(data, "obstacles", required=False)):
        where = f"obstacles[{k}]"
        kind = item.get("type")
        if not isinstance(kind, str) or kind not in OBSTACLE_FIELDS:
            raise rd.fail(
                f"{where}.type",
                f"unknown obstacle type {kind!r}; expected one of "
                f"{list(OBSTACLE_FIELDS)}",
            )
        required, optional = OBSTACLE_FIELDS[kind]
        rd.keys(item, where, {"type"} | required | optional, {"type"} | required)
        obstacles.append(Obstacle(**_obstacle_args(rd, item, where, kind, base)))
    return tuple(obstacles)


def _obstacle_args(rd: Reader, item: dict, where: str, kind: str, base: Path) -> dict:
    """The :class:`Obstacle` fields of one ``[[obstacles]]`` entry."""
    args = {"kind": kind}
    for key in ("center", "size", "a", "b"):
        if key in item:
            args[key] = tuple(rd.vector(item, key, where))
    if "size" in args and min(args["size"]) <= 0:
        raise rd.fail(
            f"{where}.size",
            f"expected positive edge lengths, got {list(args['size'])}",
        )
    for key in ("radius", "scale"):
        if key in item:
            args[key] = rd.positive(item, key, where)
    if "orientation" in item:
        args["orientation"] = tuple(
            tuple(float(v) for v in row)
            for row in _read_orientation(
                rd, item["orientation"], f"{where}.orientation"
            )
        )
    if kind == "mesh":
        args["path"] = _mesh_path(rd, item, where, base)
    return args


def _mesh_path(rd: Reader, item: dict, where: str, base: Path) -> str:
    """The mesh file, relative to the task file's folder, checked to load."""
    path = base / rd.string(item, "path", where)
    if not path.is_file():
        raise rd.fail(f"{where}.path", f"mesh file {str(path)!r} not found")
    try:
        load_mesh(str(path))
    except ValueError as err:
        raise rd.fail(f"{where}.path", str(err)) from None
    return str(path)


def _options(
    rd: Reader, data: dict, key: str, defaults: dict, integer: bool = False
) -> dict:
    table = data.get(key, {})
    if not isinstance(table, dict):
        raise rd.fail(f"[{key}]", "expected a table")
    rd.keys(table, f"[{key}]", set(defaults), set())
    out = dict(defaults)
    for name in table:
        value = rd.number(table, name, f"[{key}]")
        if value < 0 or (
            integer and (value != int(value) or (name != "seed" and value < 1))
        ):
            what = (
                "number >= 0"
                if not integer
                else "non-negative integer"
                if name == "seed"
                else "positive integer"
            )
            raise rd.fail(f"[{key}].{name}", f"expected a {what}, got {table[name]!r}")
        out[name] = int(value) if integer else value
    return out


def _read_workspace(rd: Reader, data: dict, obstacles) -> tuple:
    if "workspace" not in data:
        if obstacles:
            raise rd.fail(
                "[workspace]",
                "missing table; obstacles need the voxel grid's lower and upper "
                "corners",
            )
        return None, 0.02, 0.04
    if not isinstance(data["workspace"], dict):
        raise rd.fail(
            "[workspace]",
            "expected a table {lower, upper, voxel?, clearance?}, "
            f"got {data['workspace']!r}",
        )
    table = rd.keys(
        data["workspace"],
        "[workspace]",
        {"lower", "upper", "voxel", "clearance"},
        {"lower", "upper"},
    )
    lower, upper = (
        rd.vector(table, "lower", "[workspace]"),
        rd.vector(table, "upper", "[workspace]"),
    )
    if np.any(lower >= upper):
        raise rd.fail(
            "[workspace].upper",
            "must exceed lower in every coordinate, "
            f"got lower={list(lower)} upper={list(upper)}",
        )
    voxel = rd.positive(table, "voxel", "[workspace]") if "voxel" in table else 0.02
    clearance = (
        rd.positive(table, "clearance", "[workspace]")
        if "clearance" in table
        else 2.0 * voxel
    )
    return (lower, upper), voxel, clearance


def parse_task(data: dict, source: str, base: Path = Path(".")) -> Task:
    """Validate a parsed task file and build the :class:`Task` (arm compiled and
    checked)."""
    rd = Reader(source)
    rd.top_level(data, TOP_LEVEL)
    if not isinstance(data.get("task"), dict):
        raise rd.fail("[task]", "missing table")
    head = rd.keys(
        data["task"],
        "[task]",
        {"name", "gravity", "torque_limit", "module_radius", "payload"},
        {"name", "gravity", "torque_limit", "module_radius"},
    )
    modules, names, bounds = _read_modules(rd, data)
    d0, lower, upper, is_length = (
        (np.array(c) for c in zip(*bounds))
        if bounds
        else (np.zeros(0),) * 3 + (np.zeros(0, bool),)
    )
    payload = rd.number(head, "payload", "[task]") if "payload" in head else 0.0
    arm = make_arm(
        rd.string(head, "name", "[task]"),
        modules,
        names,
        d0,
        lower,
        upper,
        is_length,
        rd.positive(head, "torque_limit", "[task]"),
        rd.positive(head, "module_radius", "[task]"),
        source,
    )
    obstacles = _read_obstacles(rd, data, base)
    workspace, voxel, clearance = _read_workspace(rd, data, obstacles)
    return Task(
        name=arm.name,
        source=source,
        arm=arm,
        targets=_read_targets(rd, data),
        obstacles=obstacles,
        gravity=rd.vector(head, "gravity", "[task]"),
        payload=payload,
        weights=_options(rd, data, "weights", WEIGHTS),
        tolerances=_options(rd, data, "tolerances", TOLERANCES),
        solver=_options(rd, data, "solver", SOLVER, integer=True),
        workspace=workspace,
        voxel=voxel,
        clearance=clearance,
    )


def load_task(path: str | Path) -> Task:
    """Read and validate an arm task file."""
    path = Path(path)
    return parse_task(parse_text(path), str(path), path.parent)


def loads_task(text: str, source: str = "<string>") -> Task:
    """As :func:`load_task`, from the text of a file."""
    return parse_task(parse_toml(text, source), source)
