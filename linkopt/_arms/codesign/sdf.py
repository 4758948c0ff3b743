"""Obstacles, their signed distance field on a voxel grid, and the smoothed penetration
cost.

Paper 000, Sec. III-C: before optimising, the workspace is voxelised and a signed
distance field (SDF) is precomputed; the obstacle cost is the CHOMP workspace potential
(Zucker et al. 2013, eq. 21) of the SDF at points along every module, with gradients in
both the configurations and the design.

* Boxes (``size`` = full edge lengths, axis-aligned unless an ``orientation`` is given),
  spheres and capsules get their exact signed distances at the voxel centres. Mesh files
  are loaded and voxelised with trimesh (``voxelized(...).fill()``, which needs no
  spatial index) and their signed distance is the Euclidean distance transform of the
  occupancy (outside minus inside, half a voxel towards the surface), so it is accurate
  to about one voxel, as in the paper's voxel SDF.
* The field of several obstacles is the minimum of theirs. Between voxel centres it is
  interpolated trilinearly (:func:`field_distance`, differentiable); outside the grid
  the nearest boundary value is used, so the grid must enclose the arm's workspace.
* :func:`chomp_cost` is ``-D + ε/2`` inside (``D < 0``), ``(D - ε)² / (2ε)`` for
  ``0 ≤ D ≤ ε`` and 0 beyond: continuous with a continuous gradient, so a point
  approaching an obstacle is already pushed away.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np
from jax.scipy.ndimage import map_coordinates
from jaxtyping import Array, Float
from scipy.ndimage import distance_transform_edt


@dataclass(frozen=True)
class Obstacle:
    """One obstacle: ``kind`` box | sphere | capsule | mesh, in task length units.

    box: ``center``, ``size`` and optional ``orientation`` (a rotation matrix whose
    columns are the directions of the box's x, y, z edges in the world; ``None``:
    axis-aligned); sphere: ``center``, ``radius``; capsule: segment ``a``-``b`` and
    ``radius``; mesh: ``path`` (any format trimesh reads), scaled by ``scale`` then
    translated by ``center``.
    """

    kind: str
    center: tuple[float, float, float] = (0.0, 0.0, 0.0)
    size: tuple[float, float, float] = (0.0, 0.0, 0.0)
    radius: float = 0.0
    a: tuple[float, float, float] = (0.0, 0.0, 0.0)
    b: tuple[float, float, float] = (0.0, 0.0, 0.0)
    path: str = ""
    scale: float = 1.0
    orientation: tuple[tuple[float, float, float], ...] | None = None  # (3, 3), rows


class DistanceField(NamedTuple):
    """Signed distances at voxel centres ``origin + spacing · (i, j, k)``."""

    origin: np.ndarray  # (3,)
    spacing: float
    values: np.ndarray  # (nx, ny, nz)


def box_distance(points: np.ndarray, center, size, orientation=None) -> np.ndarray:
    """Exact signed distance to a box, ``(N, 3) -> (N,)``; ``orientation`` (columns: the
    edge directions in the world) rotates it about its centre, ``None`` is
    axis-aligned."""
    local = points - np.asarray(center)
    if orientation is not None:
        local = local @ np.asarray(
            orientation
        )  # world → box frame: Rᵀ (p - c), row-wise
    q = np.abs(local) - 0.5 * np.asarray(size)
    outside = np.linalg.norm(np.maximum(q, 0.0), axis=-1)
    return outside + np.minimum(np.max(q, axis=-1), 0.0)


def sphere_distance(points: np.ndarray, center, radius: float) -> np.ndarray:
    """Exact signed distance to a sphere."""
    return np.linalg.norm(points - np.asarray(center), axis=-1) - radius


def capsule_distance(points: np.ndarray, a, b, radius: float) -> np.ndarray:
    """Exact signed distance to a capsule (segment ``a``-``b`` swept by a sphere)."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    ab = b - a
    t = np.clip(((points - a) @ ab) / max(ab @ ab, 1e-300), 0.0, 1.0)
    return np.linalg.norm(points - (a + t[:, None] * ab), axis=-1) - radius


def load_mesh(path: str):
    """The triangle mesh in ``path`` (``trimesh.Trimesh``); ``ValueError`` with a
    one-line reason when the file cannot be read as a non-empty mesh."""
    import trimesh  # heavy import, only for mesh obstacles

    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as err:  # trimesh raises many kinds on corrupt or unknown files
        detail = str(err).splitlines()[0] if str(err) else "no detail"
        raise ValueError(
            f"cannot read {str(path)!r} as a mesh ({type(err).__name__}: {detail})"
        ) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise ValueError(f"{str(path)!r} holds no triangle mesh (no faces)")
    return mesh


def _mesh_distance(
    obstacle: Obstacle, grid_points: np.ndarray, shape, spacing: float
) -> np.ndarray:
    mesh = load_mesh(obstacle.path)
    mesh.apply_scale(obstacle.scale)
    mesh.apply_translation(obstacle.center)
    voxels = mesh.voxelized(spacing / 2.0).fill()
    inside = voxels.is_filled(grid_points).reshape(shape)
    if (
        not inside.any()
    ):  # the mesh misses the grid: distance to its bounding box (a lower bound)
        low, high = mesh.bounds
        return box_distance(grid_points, 0.5 * (low + high), high - low)
    outside = distance_transform_edt(~inside) * spacing
    interior = distance_transform_edt(inside) * spacing
    return np.where(
        inside, -(interior - 0.5 * spacing), outside - 0.5 * spacing
    ).ravel()


def obstacle_distance(obstacle: Obstacle, points: np.ndarray) -> np.ndarray:
    """Exact signed distance of a primitive obstacle at ``points (N, 3)``."""
    if obstacle.kind == "box":
        return box_distance(
            points, obstacle.center, obstacle.size, obstacle.orientation
        )
    if obstacle.kind == "sphere":
        return sphere_distance(points, obstacle.center, obstacle.radius)
    if obstacle.kind == "capsule":
        return capsule_distance(points, obstacle.a, obstacle.b, obstacle.radius)
    raise ValueError(f"no closed-form distance for a {obstacle.kind!r} obstacle")


def grid_shape(lower, upper, spacing: float) -> tuple[int, int, int]:
    """Voxel counts covering ``[lower, upper]`` with centres ``spacing`` apart."""
    span = np.asarray(upper, float) - np.asarray(lower, float)
    return tuple(int(np.ceil(s / spacing)) + 1 for s in span)


def build_field(
    obstacles: tuple[Obstacle, ...],
    lower,
    upper,
    spacing: float,
    empty: float | None = None,
) -> DistanceField:
    """The SDF of ``obstacles`` on the voxel grid over ``[lower, upper]``.

    With no obstacle at all every value is ``empty`` (default: the grid's diagonal, a
    distance no point of the grid is nearer to an obstacle than, in the task's units).
    The obstacles' distances are not capped.
    """
    origin = np.asarray(lower, dtype=float)
    shape = grid_shape(lower, upper, spacing)
    axes = [origin[k] + spacing * np.arange(shape[k]) for k in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    values = None
    for obstacle in obstacles:
        if obstacle.kind == "mesh":
            distance = _mesh_distance(obstacle, points, shape, spacing)
        else:
            distance = obstacle_distance(obstacle, points)
        values = distance if values is None else np.minimum(values, distance)
    if values is None:
        diagonal = float(np.linalg.norm(np.asarray(upper, float) - origin))
        values = np.full(points.shape[0], diagonal if empty is None else float(empty))
    return DistanceField(origin, float(spacing), values.reshape(shape))


def field_distance(
    field: DistanceField, points: Float[Array, "N 3"]
) -> Float[Array, " N"]:
    """Trilinear interpolation of the SDF at ``points`` (differentiable in
    ``points``)."""
    index = (jnp.asarray(points) - jnp.asarray(field.origin)) / field.spacing
    return map_coordinates(
        jnp.asarray(field.values),
        [index[:, 0], index[:, 1], index[:, 2]],
        order=1,
        mode="nearest",
    )


def chomp_cost(distance: Float[Array, ...], epsilon: float) -> Float[Array, ...]:
    """CHOMP's smoothed penetration cost of signed distances (module docstring)."""
    inside = -distance + 0.5 * epsilon
    near = 0.5 * (jnp.minimum(distance, epsilon) - epsilon) ** 2 / epsilon
    return jnp.where(distance < 0.0, inside, near)
