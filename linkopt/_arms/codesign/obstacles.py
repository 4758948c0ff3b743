"""A task's obstacles and workspace (``[[obstacles]]``, ``[workspace]``): the obstacle
shapes and meshes, the voxel grid of the workspace and its clearance, and the check
that the grids fit the memory limit.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..._errors import InputError
from ..._files.fields import Reader
from .. import limits
from .sdf import (
    MAX_CELLS,
    Obstacle,
    grid_cells,
    grid_limit_message,
    load_mesh,
    mesh_cells,
)

#: Largest length (m) of a task's positions and sizes.
MAX_LENGTH = 1e3
#: Each obstacle kind's required and optional fields.
OBSTACLE_FIELDS = {
    "box": ({"center", "size"}, {"orientation"}),
    "sphere": ({"center", "radius"}, set()),
    "capsule": ({"a", "b", "radius"}, set()),
    "mesh": ({"path"}, {"center", "scale"}),
}


def read_obstacles(
    rd: Reader, data: dict, base: Path, meshes: dict
) -> tuple[Obstacle, ...]:
    """The obstacles; ``meshes`` receives each mesh obstacle's index -> bounds."""
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
        args = _obstacle_args(rd, item, where, kind, base)
        if kind == "mesh":
            args["path"], meshes[k] = args["path"]
        obstacles.append(Obstacle(**args))
    return tuple(obstacles)


def _obstacle_args(rd: Reader, item: dict, where: str, kind: str, base: Path) -> dict:
    """The :class:`Obstacle` fields of one ``[[obstacles]]`` entry."""
    args = {"kind": kind}
    for key in ("center", "size", "a", "b"):
        if key in item:
            args[key] = tuple(limits.vector(rd, item, key, where, MAX_LENGTH))
    if "size" in args and min(args["size"]) <= 0:
        raise rd.fail(
            f"{where}.size",
            f"expected positive edge lengths, got {list(args['size'])}",
        )
    if "radius" in item:
        args["radius"] = limits.positive(rd, item, "radius", where, MAX_LENGTH)
    if "scale" in item:
        args["scale"] = limits.positive(rd, item, "scale", where)
    if "orientation" in item:
        args["orientation"] = tuple(
            tuple(float(v) for v in row)
            for row in limits.orientation(
                rd, item["orientation"], f"{where}.orientation"
            )
        )
    if kind == "mesh":
        args["path"] = _mesh_path(rd, item, where, base)
    return args


def _mesh_path(rd: Reader, item: dict, where: str, base: Path) -> tuple:
    """The mesh file, relative to the task file's folder, checked to load (a closed
    surface, finite); returns ``(path, bounds (2, 3))``."""
    path = base / rd.string(item, "path", where)
    if not path.is_file():
        raise rd.fail(f"{where}.path", f"mesh file {str(path)!r} not found")
    limits.file_size(path, lambda m: rd.fail(f"{where}.path", m), "mesh file")
    try:
        mesh = load_mesh(str(path))
    except InputError as err:
        raise rd.fail(f"{where}.path", str(err)) from None
    bounds = np.asarray(mesh.bounds, dtype=float)
    if np.abs(bounds).max() * item.get("scale", 1.0) > MAX_LENGTH:
        raise rd.fail(
            f"{where}.path",
            f"mesh extends beyond {MAX_LENGTH:g} m from the origin (after scale)",
        )
    return str(path), bounds


def read_workspace(rd: Reader, data: dict, obstacles) -> tuple:
    if "workspace" not in data:
        if obstacles:
            raise rd.fail(
                "[workspace]",
                "missing table; obstacles need the voxel grid's lower and upper "
                "corners",
            )
        return None, 0.02, 0.04, MAX_CELLS
    if not isinstance(data["workspace"], dict):
        raise rd.fail(
            "[workspace]",
            "expected a table {lower, upper, voxel?, clearance?}, "
            f"got {data['workspace']!r}",
        )
    table = rd.keys(
        data["workspace"],
        "[workspace]",
        {"lower", "upper", "voxel", "clearance", "max_cells"},
        {"lower", "upper"},
    )
    lower, upper = (
        limits.vector(rd, table, "lower", "[workspace]", MAX_LENGTH),
        limits.vector(rd, table, "upper", "[workspace]", MAX_LENGTH),
    )
    if np.any(lower >= upper):
        raise rd.fail(
            "[workspace].upper",
            "must exceed lower in every coordinate, "
            f"got lower={list(lower)} upper={list(upper)}",
        )
    voxel = (
        limits.positive(rd, table, "voxel", "[workspace]", MAX_LENGTH)
        if "voxel" in table
        else 0.02
    )
    clearance = (
        limits.positive(rd, table, "clearance", "[workspace]", MAX_LENGTH)
        if "clearance" in table
        else 2.0 * voxel
    )
    max_cells = (
        rd.positive_integer(table, "max_cells", "[workspace]")
        if "max_cells" in table
        else MAX_CELLS
    )
    return (lower, upper), voxel, clearance, max_cells


def check_grids(rd: Reader, task: dict, meshes: dict) -> None:
    """The SDF's voxel grid and every mesh's voxelisation within ``max_cells``
    (``task``: the :class:`Task` fields read so far)."""
    if not task["obstacles"]:
        return
    lower, upper = task["workspace"]
    voxel, max_cells = task["voxel"], task["max_cells"]
    message = grid_limit_message(grid_cells(lower, upper, voxel), max_cells)
    if message:
        raise rd.fail(
            "[workspace].voxel",
            f"{message}; use a larger voxel or a smaller workspace, or raise "
            "[workspace].max_cells",
        )
    for k, bounds in meshes.items():
        cells = mesh_cells(bounds, task["obstacles"][k].scale, voxel)
        message = grid_limit_message(cells, max_cells)
        if message:
            raise rd.fail(
                f"obstacles[{k}].path",
                f"the mesh's {message}; use a larger voxel or scale, or raise "
                "[workspace].max_cells",
            )
