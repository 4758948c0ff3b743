"""STL and GLB solids (issue 18): one watertight solid per body whose bounds hold every
anchor of the body at the chosen design's rest pose, thickness as asked, GLB nodes
named like the bodies and placed in metres."""

from pathlib import Path

import numpy as np
import pytest
import trimesh

import linkopt
from linkopt._export import meshes
from linkopt._export.tree import rest

ROOT = Path(__file__).resolve().parent.parent


@pytest.fixture(scope="module")
def neck():
    return linkopt.load(ROOT / "mechanisms" / "neck_2dof.toml")


def _holds(bounds, points, slack=1e-9) -> bool:
    return bool(
        np.all(points >= bounds[0] - slack) and np.all(points <= bounds[1] + slack)
    )


def _anchors_of(mech, rest_pose, body):
    on_body = np.flatnonzero((mech.joint_bodies == body).any(axis=1))
    return rest_pose.anchors[on_body]


@pytest.mark.parametrize("which", ["five_bar", "neck"])
def test_solids_are_watertight_and_hold_anchors(which, five_bar, neck):
    mech = five_bar if which == "five_bar" else neck
    design = mech.design.p0 + 0.3 * (mech.design.upper - mech.design.p0)
    rest_pose = rest(mech, design)
    assert not np.allclose(rest_pose.anchors, mech.anchors)  # the design moved them
    solids = meshes.body_meshes(mech, design)
    assert len(solids) == mech.num_bodies
    for b, solid in enumerate(solids):
        assert solid.is_watertight and solid.is_volume
        assert _holds(solid.bounds, _anchors_of(mech, rest_pose, b))
        for p in np.flatnonzero(mech.point_bodies == b):
            assert solid.contains(rest_pose.points[p][None])[0]


def test_thickness_sets_the_joint_spheres(five_bar):
    """The ground carries two anchors at x = ±20 mm: its solid spans the anchors plus
    the joint spheres' radius, 0.75 x thickness (icosphere vertices: within 5 %)."""
    for thickness in (2.0, 6.0):
        ground = meshes.body_meshes(five_bar, thickness=thickness)[five_bar.ground]
        radius = 0.75 * thickness
        low, high = ground.bounds
        assert high[2] == pytest.approx(radius, rel=0.05) and high[2] <= radius
        assert high[0] - 20.0 == pytest.approx(radius, rel=0.05)
        union_volume = ground.volume
        spheres = 2 * 4 / 3 * np.pi * radius**3
        assert spheres < union_volume < spheres + np.pi * (thickness / 2) ** 2 * 40.0


def test_glb_nodes_are_bodies_in_metres(five_bar, tmp_path):
    path = tmp_path / "five_bar.glb"
    summary = meshes.export_glb(five_bar, path)
    assert summary["watertight"]
    loaded = trimesh.load(path, force="scene")
    assert sorted(loaded.graph.nodes_geometry) == sorted(five_bar.body_names)
    rest_pose = rest(five_bar)
    for b, body in enumerate(five_bar.body_names):
        transform, geometry = loaded.graph[body]
        mesh = loaded.geometry[geometry]
        assert mesh.is_watertight
        assert np.allclose(transform[:3, 3], five_bar.body_origins[b] * 1e-3)
        world = mesh.copy().apply_transform(transform)
        assert _holds(world.bounds, _anchors_of(five_bar, rest_pose, b) * 1e-3)


def test_stl_folder_one_file_per_body(five_bar, tmp_path):
    summary = meshes.export_stl(five_bar, tmp_path / "parts")
    assert sorted(Path(f).name for f in summary["files"]) == sorted(
        f"{b}.stl" for b in five_bar.body_names
    )
    rest_pose = rest(five_bar)
    for b, body in enumerate(five_bar.body_names):
        part = trimesh.load(tmp_path / "parts" / f"{body}.stl")
        assert part.is_watertight
        assert _holds(part.bounds, _anchors_of(five_bar, rest_pose, b), slack=1e-6)


@pytest.mark.parametrize("bad", [0.0, -1.0, float("nan"), 1e6])
def test_bad_thickness_is_refused(five_bar, bad):
    with pytest.raises(linkopt.InputError, match="--thickness"):
        meshes.check_thickness(five_bar, bad)
