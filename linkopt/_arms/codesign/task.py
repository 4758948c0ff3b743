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

Physically meaningless values are refused: a link's or tool's ``length`` (fixed or its
bounds) must be positive; masses, the payload, weights and tolerances >= 0; the torque
limit, module radius, obstacle sizes and radii, voxel and clearance > 0; an approach
cone's ``angle_deg`` in (0, 180]. Absurd magnitudes and unbounded work are refused
before anything is built: lengths and coordinates
at most :data:`MAX_LENGTH` (1 km), angles at most :data:`MAX_ANGLE` (4π rad), every
other number at most 1e6 (weights 1e9); at most :data:`MAX_MODULES` modules;
``[solver]`` starts <= 1000, max_iterations <= 100000, waypoints_per_target <= 100, and
at most :data:`MAX_VARIABLES` NLP variables (waypoints × joints + design parameters:
SLSQP's matrices are dense in them); the voxel grid of the SDF (and a mesh's
voxelisation) at most ``[workspace] max_cells`` voxels (default
:data:`~linkopt._arms.codesign.sdf.MAX_CELLS`, about 4 GB while it is built); task files
at most 16 MiB.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from jaxtyping import Float

from ..._errors import MechanismFileError
from ..._files.fields import Reader, parse_text, parse_toml
from .. import limits
from .model import LENGTH_SLOTS, SLOTS, Arm, Module, make_arm
from .obstacles import (
    MAX_LENGTH,
    check_grids,
    read_obstacles,
    read_workspace,
)
from .sdf import (
    MAX_CELLS,
    Obstacle,
)

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
#: Largest value of each option (module docstring); ``seed`` is unbounded.
LIMITS = {
    "weights": 1e9,
    "tolerances": limits.MAX_MAGNITUDE,
    "solver": {"starts": 1000, "max_iterations": 100_000, "waypoints_per_target": 100},
}
MAX_ANGLE = 4 * math.pi
MAX_MODULES = 200
MAX_VARIABLES = 2000


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
    max_cells: int = MAX_CELLS


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
            _slot_value(rd, value, "min", f"{where}.{slot}", slot),
            _slot_value(rd, value, "max", f"{where}.{slot}", slot),
        )
        if low >= high:
            raise rd.fail(
                f"{where}.{slot}", f"needs min < max, got min={low} and max={high}"
            )
        init = (
            _slot_value(rd, value, "init", f"{where}.{slot}", slot)
            if "init" in value
            else 0.5 * (low + high)
        )
        if not low <= init <= high:
            raise rd.fail(f"{where}.{slot}.init", f"{init} is outside [{low}, {high}]")
        names.append(f"{item.get('name', where)}.{slot}")
        bounds.append((init, low, high, slot in LENGTH_SLOTS))
        return (len(names) - 1, init)
    return (-1, _slot_value(rd, item, slot, where, slot))


def _slot_value(rd: Reader, data: dict, key: str, where: str, slot: str) -> float:
    """A slot's value or bound: a length > 0, a coordinate or an angle of bounded
    magnitude (module docstring)."""
    if slot == "length":
        return limits.positive(rd, data, key, where, MAX_LENGTH)
    if slot in LENGTH_SLOTS:
        return limits.number(rd, data, key, where, MAX_LENGTH, " m")
    return limits.number(rd, data, key, where, MAX_ANGLE, " rad")


def _read_modules(rd: Reader, data: dict) -> tuple[tuple[Module, ...], list, list]:
    items = rd.entries(data, "modules", required=True)
    limits.count_limit(rd, "[[modules]]", len(items), MAX_MODULES, "modules")
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
        if "name" in item:
            rd.string(item, "name", where)
        mass = (
            limits.non_negative(rd, item, "mass", where, "mass")
            if "mass" in item
            else 0.0
        )
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
        axis = limits.direction(rd, item, "axis", where) if "axis" in item else None
        orientation = (
            limits.orientation(rd, item["orientation"], f"{where}.orientation")
            if "orientation" in item
            else None
        )
        approach = (
            _read_approach(rd, item["approach"], f"{where}.approach")
            if "approach" in item
            else None
        )
        position = limits.vector(rd, item, "position", where, MAX_LENGTH)
        targets.append(Target(position, axis, orientation, approach))
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
    if angle > 180:
        raise rd.fail(
            f"{where}.angle_deg", f"expected an angle in (0, 180] degrees, got {angle}"
        )
    return (
        limits.direction(rd, cone, "local", where),
        limits.direction(rd, cone, "direction", where),
        math.cos(math.radians(angle)),
    )


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
        _option_limit(rd, table, key, name)
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


def _option_limit(rd: Reader, table: dict, key: str, name: str) -> None:
    """An option within its table's limit (:data:`LIMITS`)."""
    limit = LIMITS[key].get(name) if isinstance(LIMITS[key], dict) else LIMITS[key]
    if limit is not None and table[name] > limit:
        raise rd.fail(
            f"[{key}].{name}",
            f"{table[name]!r} exceeds the limit of {limit:g}",
        )


def _check_size(rd: Reader, task: dict, modules: tuple, design: int) -> None:
    """At most :data:`MAX_VARIABLES` NLP variables (module docstring)."""
    waypoints = task["solver"]["waypoints_per_target"] * len(task["targets"])
    joints = sum(m.kind == "joint" for m in modules)
    variables = waypoints * joints + design
    if variables > MAX_VARIABLES:
        raise rd.fail(
            "[solver].waypoints_per_target",
            f"the NLP would have {variables} variables ({waypoints} waypoints x "
            f"{joints} joints + {design} design parameters; SLSQP's dense matrices "
            f"need ~{8 * variables**2 / 1e6:.3g} MB and ~{variables**3:.2g} flops per "
            f"iteration), over the limit of {MAX_VARIABLES}; use fewer "
            "waypoints_per_target or targets",
        )


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
    fields = _read_rest(rd, data, head, base)
    _check_size(rd, fields, modules, len(names))
    arm = make_arm(
        rd.string(head, "name", "[task]"),
        modules,
        names,
        d0,
        lower,
        upper,
        is_length,
        limits.positive(rd, head, "torque_limit", "[task]"),
        limits.positive(rd, head, "module_radius", "[task]", MAX_LENGTH),
        source,
    )
    return Task(name=arm.name, source=source, arm=arm, **fields)


def _read_rest(rd: Reader, data: dict, head: dict, base: Path) -> dict:
    """Every :class:`Task` field but the arm, checked (before the arm is built)."""
    meshes: dict = {}
    obstacles = read_obstacles(rd, data, base, meshes)
    workspace, voxel, clearance, max_cells = read_workspace(rd, data, obstacles)
    fields = {
        "targets": _read_targets(rd, data),
        "obstacles": obstacles,
        "gravity": limits.vector(rd, head, "gravity", "[task]"),
        "payload": (
            limits.non_negative(rd, head, "payload", "[task]", "payload (kg)")
            if "payload" in head
            else 0.0
        ),
        "weights": _options(rd, data, "weights", WEIGHTS),
        "tolerances": _options(rd, data, "tolerances", TOLERANCES),
        "solver": _options(rd, data, "solver", SOLVER, integer=True),
        "workspace": workspace,
        "voxel": voxel,
        "clearance": clearance,
        "max_cells": max_cells,
    }
    check_grids(rd, fields, meshes)
    return fields


def load_task(path: str | Path) -> Task:
    """Read and validate an arm task file."""
    path = Path(path)
    limits.file_size(path, lambda m: MechanismFileError(str(path), "", m), "task file")
    return parse_task(parse_text(path), str(path), path.parent)


def loads_task(text: str, source: str = "<string>") -> Task:
    """As :func:`load_task`, from the text of a file."""
    return parse_task(parse_toml(text, source), source)
