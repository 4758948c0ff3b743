"""``linkopt export --format dxf|svg`` (issue 42): sheet drawings of planar links read
back with ezdxf and an XML parser. Each link's holes sit at its joints' anchors at the
rest pose of the design exported (read from the engine's state read-out, not from the
exporter's geometry), one layer per body, its outline wraps the holes, its texts name
the link and its centre distances; a spatial mechanism is refused in one line."""

import math
import xml.etree.ElementTree as ET
from pathlib import Path

import ezdxf
import numpy as np
import pytest

import linkopt
from linkopt._cli.main import main
from linkopt._engine.geometry import rest_state
from linkopt._engine.readout import joint_positions, point_positions

ROOT = Path(__file__).resolve().parent.parent
MECHANISMS = ROOT / "mechanisms"
SVG = "{http://www.w3.org/2000/svg}"
INKSCAPE = "{http://www.inkscape.org/namespaces/inkscape}"


def _export(capsys, name, fmt, out, *extra):
    code = main(
        ["export", str(MECHANISMS / name), "--format", fmt, "--out", str(out), *extra]
    )
    return code, capsys.readouterr().err


def _design(mech):
    """A design away from the file's: a quarter of the way to the upper bounds."""
    return mech.design.p0 + 0.25 * (mech.design.upper - mech.design.p0)


def _anchors(mech, design) -> np.ndarray:
    """The joint anchors at rest in the drawing's plane (z = 0 for these files)."""
    world = np.asarray(joint_positions(mech, rest_state(mech), design=design))
    assert np.allclose(world[:, 2], 0.0, atol=1e-12)
    return world[:, :2]


def _expected_holes(mech, design) -> dict:
    anchors = _anchors(mech, design)
    return {
        name: {mech.joint_names[j]: anchors[j] for j in mech.joints_on(b)}
        for b, name in enumerate(mech.body_names)
    }


def _match(found: np.ndarray, expected: np.ndarray) -> float:
    """Largest distance of the closest pairing of two point sets (same size)."""
    assert found.shape == expected.shape
    worst = 0.0
    left = list(range(len(found)))
    for e in expected:
        k = min(left, key=lambda i: np.linalg.norm(found[i] - e))
        worst = max(worst, float(np.linalg.norm(found[k] - e)))
        left.remove(k)
    return worst


CASES = [
    ("five_bar.toml", True, 4),  # mm, with --design
    ("jansen_1dof.toml", False, 5),  # cm, the file's design
    ("four_bar_collision.toml", False, 4),  # [collision] radii
]


@pytest.mark.parametrize("name, with_design, units", CASES)
def test_dxf_holes_at_the_anchors(name, with_design, units, tmp_path, capsys):
    mech = linkopt.load(str(MECHANISMS / name))
    design = _design(mech) if with_design else mech.design.p0
    extra = ["--design", ",".join(f"{v:.17g}" for v in design)] if with_design else []
    code, err = _export(capsys, name, "dxf", tmp_path / "links.dxf", *extra)
    assert code == 0, err
    doc = ezdxf.readfile(tmp_path / "links.dxf")
    assert doc.header["$INSUNITS"] == units
    msp = doc.modelspace()
    expected = _expected_holes(mech, design)
    for b, body in enumerate(mech.body_names):
        assert body in doc.layers
        on = [e for e in msp if e.dxf.layer == body]
        radius = _capsule_radius(mech, b)
        holes = np.array(
            [
                (e.dxf.center.x, e.dxf.center.y)
                for e in on
                if e.dxftype() == "CIRCLE" and math.isclose(e.dxf.radius, radius / 2)
            ]
        ).reshape(-1, 2)
        want = np.array(list(expected[body].values())).reshape(-1, 2)
        assert _match(holes, want) <= 1e-9 * mech.length_scale, body
        outlines = [e for e in on if e.dxftype() == "LWPOLYLINE"]
        if len(want) >= 2:
            (outline,) = outlines
            _check_outline(outline, want, _points(mech, design, b), 1.5 * radius)
        texts = [e.dxf.text for e in on if e.dxftype() == "TEXT"]
        assert body in texts
        if len(want) == 2 and len(mech.joints_on(b)) == 2:
            d = np.linalg.norm(want[0] - want[1])
            assert f"{d:.6g} {mech.raw['mechanism']['units']}" in texts


def _capsule_radius(mech, body: int) -> float:
    if mech.collision is not None:
        return float(mech.collision.body_radii[body])
    return 0.5 * 0.04 * mech.length_scale  # the default thickness, 4 % of the length


def _points(mech, design, body: int) -> np.ndarray:
    """The body's named points at rest in the drawing's plane."""
    world = np.asarray(point_positions(mech, rest_state(mech), design=design))
    return world[mech.point_bodies == body][:, :2]


def _check_outline(polyline, holes, points, radius: float) -> None:
    """Closed and convex (its arcs turn 2π in all), each corner ``radius`` from a
    hole or named point, and every hole and point at least ``radius`` inside each
    straight edge."""
    holes = np.concatenate([holes, points])
    assert polyline.closed
    points = np.array([(x, y, b) for x, y, *_, b in polyline.get_points("xyseb")])
    turns = 4 * np.arctan(points[:, 2])
    assert np.isclose(turns.sum(), 2 * np.pi)
    xy = points[:, :2]
    for p in xy:
        assert np.min(np.linalg.norm(holes - p, axis=1)) <= radius * (1 + 1e-9) + 1e-9
    for k in range(len(xy)):
        if points[k, 2] == 0:  # a straight edge from k to k + 1, outward normal right
            a, b = xy[k], xy[(k + 1) % len(xy)]
            edge = (b - a) / np.linalg.norm(b - a)
            normal = np.array([edge[1], -edge[0]])
            assert np.all((holes - a) @ normal <= -radius + 1e-9)


@pytest.mark.parametrize("name, with_design, units", CASES[:2])
def test_svg_holes_at_the_anchors(name, with_design, units, tmp_path, capsys):
    mech = linkopt.load(str(MECHANISMS / name))
    design = _design(mech) if with_design else mech.design.p0
    extra = ["--design", ",".join(f"{v:.17g}" for v in design)] if with_design else []
    code, err = _export(capsys, name, "svg", tmp_path / "links.svg", *extra)
    assert code == 0, err
    root = ET.parse(tmp_path / "links.svg").getroot()
    unit = mech.raw["mechanism"]["units"]
    width = root.get("width")
    assert width.endswith(unit)
    view = [float(v) for v in root.get("viewBox").split()]
    assert math.isclose(float(width[: -len(unit)]), view[2], rel_tol=1e-5)
    expected = _expected_holes(mech, design)
    groups = {g.get(f"{INKSCAPE}label"): g for g in root.iter(f"{SVG}g")}
    assert set(groups) == set(mech.body_names)
    for body, joints in expected.items():
        holes = {
            c.get("data-joint"): np.array([float(c.get("cx")), -float(c.get("cy"))])
            for c in groups[body].iter(f"{SVG}circle")
            if c.get("class") == "hole"
        }
        assert set(holes) == set(joints)
        for joint, at in joints.items():
            assert np.linalg.norm(holes[joint] - at) <= 1e-9 * mech.length_scale
        texts = [t.text for t in groups[body].iter(f"{SVG}text")]
        assert body in texts


def test_thickness_sizes_the_holes(tmp_path, capsys):
    code, err = _export(
        capsys, "five_bar.toml", "dxf", tmp_path / "a.dxf", "--thickness", "8"
    )
    assert code == 0, err
    msp = ezdxf.readfile(tmp_path / "a.dxf").modelspace()
    radii = sorted({round(e.dxf.radius, 12) for e in msp if e.dxftype() == "CIRCLE"})
    assert radii == [2.0]  # a quarter of the thickness; no link has one place


@pytest.mark.parametrize("fmt", ["dxf", "svg"])
def test_a_spatial_mechanism_is_refused(fmt, tmp_path, capsys):
    out = tmp_path / f"delta.{fmt}"
    code, err = _export(capsys, "delta.toml", fmt, out)
    assert code == 2
    assert len(err.strip().splitlines()) == 1
    assert "spherical" in err and "planar" in err
    assert not out.exists()
