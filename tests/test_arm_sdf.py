"""Voxel signed distance field: interpolated values and gradients against the analytic
box and sphere distances, a trimesh box mesh against the analytic box, and the CHOMP
cost's continuity."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import linkopt  # noqa: F401  (float64)
from linkopt._arms.codesign.sdf import (
    Obstacle,
    box_distance,
    build_field,
    chomp_cost,
    field_distance,
    sphere_distance,
)

H = 0.02
LOWER, UPPER = [-0.5, -0.5, -0.5], [0.5, 0.5, 0.5]
BOX = Obstacle("box", center=(0.1, -0.05, 0.0), size=(0.3, 0.2, 0.4))
SPHERE = Obstacle("sphere", center=(-0.2, 0.15, 0.1), radius=0.12)


def _points(seed, count=400):
    return np.random.default_rng(seed).uniform(-0.45, 0.45, (count, 3))


def _box_gradient(p):
    """Analytic gradient of the box distance: the outward direction from the nearest
    surface point outside, the normal of the nearest face inside."""
    rel = p - np.array(BOX.center)
    q = np.abs(rel) - 0.5 * np.array(BOX.size)
    outside = np.maximum(q, 0.0)
    norm = np.linalg.norm(outside, axis=1, keepdims=True)
    face = np.eye(3)[np.argmax(q, axis=1)]
    return np.sign(rel) * np.where(
        norm > 0, outside / np.where(norm > 0, norm, 1.0), face
    )


@pytest.mark.parametrize(
    "obstacle, exact",
    [
        (BOX, lambda p: box_distance(p, BOX.center, BOX.size)),
        (SPHERE, lambda p: sphere_distance(p, SPHERE.center, SPHERE.radius)),
    ],
)
def test_values_match_analytic_distance(obstacle, exact):
    field = build_field((obstacle,), LOWER, UPPER, H)
    p = _points(0)
    got = np.asarray(field_distance(field, jnp.asarray(p)))
    # Trilinear interpolation of a 1-Lipschitz function: error well below a voxel.
    np.testing.assert_allclose(got, exact(p), atol=0.25 * H)


def test_gradients_match_analytic_normals():
    field = build_field((BOX, SPHERE), LOWER, UPPER, H)
    p = _points(1, 2000)
    d_box = box_distance(p, BOX.center, BOX.size)
    d_sph = sphere_distance(p, SPHERE.center, SPHERE.radius)
    # Face regions of the box (away from its edges and medial planes) and away from the
    # sphere's centre, where the SDF is smooth.
    q = np.abs(p - np.array(BOX.center)) - 0.5 * np.array(BOX.size)
    gaps = np.sort(q, axis=1)
    clean_box = (
        (d_box < d_sph - 3 * H)
        & (gaps[:, 2] - gaps[:, 1] > 3 * H)
        & (gaps[:, 1] < -2 * H)
        & (np.abs(d_box) > 2 * H)
    )
    clean_sph = (d_sph < d_box - 3 * H) & (np.abs(d_sph + SPHERE.radius) > 3 * H)
    grad = np.asarray(
        jax.vmap(jax.grad(lambda x: field_distance(field, x[None])[0]))(jnp.asarray(p))
    )
    np.testing.assert_allclose(grad[clean_box], _box_gradient(p[clean_box]), atol=0.05)
    normal = (p - np.array(SPHERE.center)) / np.linalg.norm(
        p - np.array(SPHERE.center), axis=1, keepdims=True
    )
    np.testing.assert_allclose(grad[clean_sph], normal[clean_sph], atol=0.1)
    assert clean_box.sum() > 100 and clean_sph.sum() > 50


def test_mesh_obstacle_matches_box(tmp_path):
    import trimesh

    path = tmp_path / "box.stl"
    trimesh.creation.box(extents=BOX.size).export(path)
    field = build_field(
        (Obstacle("mesh", center=BOX.center, path=str(path)),), LOWER, UPPER, H
    )
    p = _points(2)
    got = np.asarray(field_distance(field, jnp.asarray(p)))
    np.testing.assert_allclose(got, box_distance(p, BOX.center, BOX.size), atol=1.5 * H)


def test_chomp_cost_is_smooth_and_vanishes_beyond_clearance():
    eps = 0.05
    d = jnp.linspace(-0.1, 0.1, 2001)
    cost = chomp_cost(d, eps)
    slope = jax.vmap(jax.grad(lambda x: chomp_cost(x, eps)))(d)
    assert float(jnp.max(jnp.abs(jnp.diff(cost)))) < 1.01e-4  # |slope| <= 1, step 1e-4
    assert float(jnp.max(jnp.abs(jnp.diff(slope)))) < 1e-2
    assert float(jnp.max(cost[d > eps])) == 0.0
    np.testing.assert_allclose(slope[d < 0], -1.0)


def test_millimetre_task_far_from_obstacles_has_no_obstacle_cost():
    """Regression: the field was capped at 1 length unit, so in a task in mm every point
    was inside the CHOMP penalty band (clearance 40 mm)."""
    ball = Obstacle("sphere", center=(0.0, 0.0, 0.0), radius=50.0)
    field = build_field((ball,), (-500.0,) * 3, (500.0,) * 3, 20.0)
    far = np.array([[400.0, 0.0, 0.0], [0.0, -300.0, 300.0], [150.0, 150.0, -150.0]])
    distance = field_distance(field, jnp.asarray(far))
    np.testing.assert_allclose(
        np.asarray(distance), sphere_distance(far, ball.center, ball.radius), atol=5.0
    )
    assert float(jnp.sum(chomp_cost(distance, 40.0))) == 0.0
    empty = build_field((), (-500.0,) * 3, (500.0,) * 3, 100.0)
    assert (
        float(jnp.sum(chomp_cost(field_distance(empty, jnp.asarray(far)), 40.0))) == 0.0
    )


def test_rotated_box_matches_the_box_in_its_own_frame():
    """A box turned 30° about z and 20° about x: its field at world points equals the
    axis-aligned box's distance at the same points expressed in the box's frame, and a
    point just outside the middle of a turned face is at the offset along that face's
    normal (not along a world axis)."""
    c, s = np.cos(np.radians(30)), np.sin(np.radians(30))
    rz = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
    c, s = np.cos(np.radians(20)), np.sin(np.radians(20))
    rx = np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    rot = rz @ rx
    box = Obstacle(
        "box", center=BOX.center, size=BOX.size, orientation=tuple(map(tuple, rot))
    )
    p = _points(2)
    local = (p - np.array(BOX.center)) @ rot  # rows: Rᵀ (p - c)
    exact = box_distance(local, (0.0, 0.0, 0.0), BOX.size)
    np.testing.assert_allclose(
        box_distance(p, box.center, box.size, box.orientation), exact, atol=1e-12
    )
    field = build_field((box,), LOWER, UPPER, H)
    np.testing.assert_allclose(
        np.asarray(field_distance(field, jnp.asarray(p))), exact, atol=0.25 * H
    )
    face_point = np.array(BOX.center) + rot[:, 0] * (0.5 * BOX.size[0] + 0.05)
    assert box_distance(face_point[None], box.center, box.size, box.orientation)[
        0
    ] == pytest.approx(0.05)


def test_rotated_box_is_drawn_with_its_turned_edges():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from linkopt._draw.arms.codesign import draw_obstacle

    quarter = ((0.0, -1.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.0, 1.0))  # 90° about z
    box = Obstacle(
        "box", center=(0.0, 0.0, 0.0), size=(0.4, 0.1, 0.2), orientation=quarter
    )
    ax = plt.figure().add_subplot(projection="3d")
    draw_obstacle(ax, box, (np.full(3, -1.0), np.full(3, 1.0)))
    ends = np.array([np.array(line.get_data_3d()).T for line in ax.lines])  # (12, 2, 3)
    plt.close("all")
    assert ends.shape == (12, 2, 3)
    # the 0.4 m edges now run along world y, the 0.1 m ones along x
    np.testing.assert_allclose(
        np.abs(ends[..., :2]).max(axis=(0, 1)), [0.05, 0.2], atol=1e-12
    )


def test_a_grid_over_the_limit_is_refused_before_allocating():
    from linkopt import InputError

    with pytest.raises(InputError, match="voxel grid of 8e\\+15 cells") as err:
        build_field((BOX,), [-1, -1, -1], [1, 1, 1], 1e-5)
    assert "\n" not in str(err.value) and "use a larger voxel" in str(err.value)
    field = build_field((BOX,), [-1, -1, -1], [1, 1, 1], 0.1, max_cells=10_000)
    assert field.values.shape == (21, 21, 21)


def test_unknown_obstacle_kind_is_an_input_error():
    from linkopt import InputError
    from linkopt._arms.codesign.sdf import obstacle_distance

    with pytest.raises(InputError, match="'cone'"):
        obstacle_distance(Obstacle("cone"), np.zeros((1, 3)))


def test_open_mesh_is_an_input_error(tmp_path):
    from linkopt import InputError
    from linkopt._arms.codesign.sdf import load_mesh

    path = tmp_path / "tri.obj"
    path.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match="not a closed \\(watertight\\) surface"):
        load_mesh(str(path))
