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

Size limit: building the field holds about :data:`BYTES_PER_CELL` bytes per voxel (the
grid's points, each obstacle's distances and their minimum), so a grid of more than
``max_cells`` voxels (default :data:`MAX_CELLS`, about 4 GB) is refused before anything
is allocated (:func:`check_grid`); a task raises it with ``[workspace] max_cells``.
A mesh obstacle must be a closed (watertight) surface, else its inside is undefined.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np
from jax.scipy.ndimage import map_coordinates
from jaxtyping import Array, Float
from scipy.ndimage import distance_transform_edt

from ... import _config  # noqa: F401  (float64 on before any array)
from ..._errors import InputError

#: Default limit on the voxels of a distance field (and of a mesh's voxelisation).
MAX_CELLS = 20_000_000
#: Peak bytes per voxel while :func:`build_field` runs (measured: 88-144 for spheres,
#: capsules and boxes; a mesh's distance transforms add some).
BYTES_PER_CELL = 200


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


@dataclass(frozen=True)
class DistanceField:
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
    """The closed triangle mesh in ``path`` (``trimesh.Trimesh``); :class:`InputError`
    with a one-line reason when the file cannot be read as a non-empty, watertight
    mesh."""
    import trimesh  # heavy import, only for mesh obstacles

    try:
        mesh = trimesh.load(path, force="mesh")
    except Exception as err:  # trimesh raises many kinds on corrupt or unknown files
        detail = str(err).splitlines()[0] if str(err) else "no detail"
        raise InputError(
            f"cannot read {str(path)!r} as a mesh ({type(err).__name__}: {detail})"
        ) from None
    if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
        raise InputError(f"{str(path)!r} holds no triangle mesh (no faces)")
    if not np.all(np.isfinite(mesh.vertices)):
        raise InputError(f"{str(path)!r} has vertices that are not finite numbers")
    if not mesh.is_watertight:
        raise InputError(
            f"{str(path)!r} is not a closed (watertight) surface, so its inside is "
            "undefined"
        )
    return mesh


def grid_cells(lower, upper, spacing: float) -> float:
    """The voxels of the grid over ``[lower, upper]`` (a float: it may be huge)."""
    span = np.asarray(upper, float) - np.asarray(lower, float)
    return float(np.prod(np.ceil(span / float(spacing)) + 1.0))


def grid_limit_message(cells: float, max_cells: float) -> str | None:
    """Why a grid of ``cells`` voxels is refused, or ``None`` when it is within
    ``max_cells``."""
    if cells <= max_cells:
        return None
    return (
        f"voxel grid of {cells:.2g} cells ({_size(cells * BYTES_PER_CELL)}) exceeds "
        f"the limit of {max_cells:.2g} cells ({_size(max_cells * BYTES_PER_CELL)})"
    )


def _size(nbytes: float) -> str:
    for unit, scale in (("TB", 1e12), ("GB", 1e9), ("MB", 1e6)):
        if nbytes >= scale:
            return f"{nbytes / scale:.3g} {unit}"
    return f"{nbytes / 1e3:.3g} kB"


def check_grid(lower, upper, spacing: float, max_cells: float = MAX_CELLS) -> None:
    """:class:`InputError` before a grid larger than ``max_cells`` is allocated."""
    if not (np.isfinite(spacing) and spacing > 0):
        raise InputError(f"voxel: expected a finite positive size, got {spacing!r}")
    message = grid_limit_message(grid_cells(lower, upper, spacing), max_cells)
    if message:
        raise InputError(f"{message}; use a larger voxel or a smaller workspace")


def mesh_cells(bounds, scale: float, spacing: float) -> float:
    """The voxels of a mesh's voxelisation (pitch half a voxel over its scaled
    bounds)."""
    low, high = np.asarray(bounds, float) * scale
    return grid_cells(low, high, spacing / 2.0)


def _mesh_distance(
    obstacle: Obstacle,
    grid_points: np.ndarray,
    shape,
    spacing: float,
    max_cells: float = MAX_CELLS,
) -> np.ndarray:
    mesh = load_mesh(obstacle.path)
    message = grid_limit_message(
        mesh_cells(mesh.bounds, obstacle.scale, spacing), max_cells
    )
    if message:
        raise InputError(f"{obstacle.path}: mesh {message}; use a larger voxel")
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
    raise InputError(
        f"obstacle: no closed-form distance for a {obstacle.kind!r} obstacle; expected "
        "box, sphere or capsule"
    )


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
    max_cells: float = MAX_CELLS,
) -> DistanceField:
    """The SDF of ``obstacles`` on the voxel grid over ``[lower, upper]``.

    With no obstacle at all every value is ``empty`` (default: the grid's diagonal, a
    distance no point of the grid is nearer to an obstacle than, in the task's units).
    The obstacles' distances are not capped. A grid of more than ``max_cells`` voxels
    is an :class:`InputError` (:func:`check_grid`).
    """
    check_grid(lower, upper, spacing, max_cells)
    origin = np.asarray(lower, dtype=float)
    shape = grid_shape(lower, upper, spacing)
    axes = [origin[k] + spacing * np.arange(shape[k]) for k in range(3)]
    points = np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)
    values = None
    for obstacle in obstacles:
        if obstacle.kind == "mesh":
            distance = _mesh_distance(obstacle, points, shape, spacing, max_cells)
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
