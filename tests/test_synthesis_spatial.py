"""Issue 41's breadth cases as shipped files: a spatial RSSR function generator
(``mechanisms/rssr.toml``), a spherical four-bar path (``spherical_four_bar.toml``)
and the Jansen leg's foot path from a perturbed leg (``jansen_foot_path.toml``).

Each file is checked against what does not come from linkopt: the RSSR's output
against the closed form of its input-output equation, the spherical four-bar's
coupler point against its cone-intersection closed form and its sphere, the Jansen
file's lengths against Jansen's numbers and its target against the shipped leg.
The targets are met exactly by the design they were written from (RMS ~ 0, no
defect over the dense cycle) and missed by the file's own design, so a synthesis
has work to do. Long synthesis runs are in
``benchmarks/bench_synthesis_spatial.py``.
"""

from __future__ import annotations

import importlib.util

import numpy as np
import pytest
from conftest import MECHANISMS, ROOT

import linkopt
from linkopt._synth.cycle import sweep_cycle
from linkopt._synth.run import score_design
from linkopt._synth.targets import targets_of


def _generator():
    path = ROOT / "benchmarks" / "synthesis_spatial" / "generate.py"
    spec = importlib.util.spec_from_file_location("synthesis_spatial_generate", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


gen = _generator()


@pytest.fixture(scope="module")
def rssr():
    return linkopt.load(MECHANISMS / "rssr.toml")


@pytest.fixture(scope="module")
def spherical():
    return linkopt.load(MECHANISMS / "spherical_four_bar.toml")


@pytest.fixture(scope="module")
def jansen():
    return linkopt.load(MECHANISMS / "jansen_foot_path.toml")


def _rssr_closed_form(mech, design, inputs):
    """The output angle from the closed form, the geometry read off the file (the
    design moves B.x, C.y, C.z)."""
    joints = dict(zip(mech.joint_names, mech.anchors))
    b0, c0 = joints["B"].copy(), joints["C"].copy()
    b0[0], c0[1], c0[2] = design
    axes = dict(zip(mech.joint_names, mech.axes))
    a, u = joints["A"], axes["A"] / np.linalg.norm(axes["A"])
    d, w = joints["D"], axes["D"] / np.linalg.norm(axes["D"])
    return gen.rssr_output(a, u, b0, d, w, c0, inputs)


def test_rssr_output_follows_the_closed_form_input_output_equation(rssr):
    # 241 inputs: the 256-row path program of the 240-step cycle sweep below
    inputs = np.linspace(-np.pi, np.pi, 241)
    w = dict(zip(rssr.joint_names, rssr.axes))["D"]
    assert abs(w @ [0.0, 0.0, 1.0]) < 1e-12  # the output axis is skew to the input's
    for design in (rssr.design.p0, gen.RSSR_TARGET):
        sol = linkopt.solve_fk_path(rssr, inputs[:, None], design=design)
        assert bool(np.all(sol.converged))  # the crank turns fully
        out = np.asarray(linkopt.output_values(rssr, sol.state, design=design))[:, 0]
        expected = _rssr_closed_form(rssr, design, inputs)
        np.testing.assert_allclose(out, expected, rtol=0, atol=1e-9)
        assert np.ptp(out) > 0.3  # a real function, not a constant


def test_rssr_table_is_the_target_design_s_closed_form(rssr):
    targets = targets_of(rssr)
    assert targets.kind == "function" and targets.name == "rocker"
    inputs = np.asarray(targets.motors)[:, 0]
    expected = _rssr_closed_form(rssr, gen.RSSR_TARGET, inputs)
    np.testing.assert_allclose(targets.values, expected, rtol=0, atol=1e-12)
    swing = np.ptp(targets.values)
    assert targets.tolerance <= 0.01 * swing


def _spherical_axes(mech, design=None):
    """The joint axes of a design, read from its rest anchors (each anchor lies at
    the sphere's radius times its axis, and a twist keeps it so)."""
    design = mech.design.p0 if design is None else design
    rest = linkopt.rest_state(mech)  # the same for every design
    joints = np.asarray(linkopt.joint_positions(mech, rest, design=design))
    return tuple(joints[k] / np.linalg.norm(joints[k]) for k in range(4))


def test_spherical_four_bar_axes_meet_at_the_centre(spherical):
    axes = np.asarray(spherical.axes, dtype=float)
    axes = axes / np.linalg.norm(axes, axis=1)[:, None]
    radii = np.linalg.norm(spherical.anchors, axis=1)
    np.testing.assert_allclose(radii, gen.SPHERE, rtol=0, atol=1e-9)
    np.testing.assert_allclose(spherical.anchors, gen.SPHERE * axes, atol=1e-9)


def test_spherical_coupler_curve_is_on_the_sphere_and_the_closed_form(spherical):
    # 241 angles: the 256-row path program of the 240-step cycle sweep below
    thetas = np.linspace(0.0, 2.0 * np.pi, 241)
    point = dict(zip(spherical.point_names, spherical.point_positions))["coupler_point"]
    for design in (spherical.design.p0, gen.SPHERICAL_TARGET):
        sol = linkopt.solve_fk_path(spherical, thetas[:, None], design=design)
        assert bool(np.all(sol.converged))  # a crank-rocker: the crank turns fully
        traced = linkopt.named_points(spherical, sol.state, design=design)
        traced = traced["coupler_point"]
        radius = np.linalg.norm(traced, axis=1)
        np.testing.assert_allclose(radius, np.linalg.norm(point), rtol=0, atol=1e-9)
        expected = gen.spherical_coupler(
            _spherical_axes(spherical, design), point, thetas
        )
        np.testing.assert_allclose(traced, expected, rtol=0, atol=1e-8)
        np.testing.assert_allclose(traced[-1], traced[0], atol=1e-8)  # closed


def test_spherical_target_is_the_target_design_s_coupler_curve(spherical):
    targets = targets_of(spherical)
    assert targets.kind == "path" and targets.closed
    point = dict(zip(spherical.point_names, spherical.point_positions))["coupler_point"]
    axes = _spherical_axes(spherical, gen.SPHERICAL_TARGET)
    thetas = 2.0 * np.pi * np.arange(targets.count) / targets.count
    expected = gen.spherical_coupler(axes, point, thetas)
    np.testing.assert_allclose(targets.values, expected, rtol=0, atol=1e-9)
    extent = np.ptp(targets.values, axis=0).max()
    assert targets.tolerance <= 0.01 * extent


JANSEN_LINKS = {  # Jansen's letter: the two joints (or the point G) it joins
    "a_l": ("O", "A_triangle"),
    "b": ("A_triangle", "B"),
    "c": ("A_triangle", "D_kc"),
    "d": ("A_triangle", "E"),
    "e": ("B", "E"),
    "f": ("E", "F"),
    "g": ("D_kc", "F"),
    "j": ("C_j", "B"),
    "k": ("C_j", "D_kc"),
    "m": ("O", "C_j"),
}


def _lengths(mech) -> dict:
    joints = dict(zip(mech.joint_names, mech.anchors))
    return {
        k: np.linalg.norm(joints[p] - joints[q]) for k, (p, q) in JANSEN_LINKS.items()
    }


def test_jansen_file_is_the_leg_perturbed_by_at_most_five_percent(jansen):
    shipped = _lengths(linkopt.load(MECHANISMS / "jansen_1dof.toml"))
    perturbed = _lengths(jansen)
    ratios = np.array([perturbed[k] / shipped[k] for k in JANSEN_LINKS])
    assert np.all(np.abs(ratios - 1.0) <= 0.05 + 1e-12)
    assert np.sum(np.abs(ratios - 1.0) > 0.01) >= 5  # really perturbed
    jansen_numbers = {k: gen.JANSEN[k] for k in "bcdefgjkm"}
    file_numbers = _lengths(linkopt.load(MECHANISMS / "jansen_1dof.toml"))
    for k, v in jansen_numbers.items():
        assert file_numbers[k] == pytest.approx(v, abs=1e-9)


def test_jansen_target_is_the_shipped_leg_s_foot_path(jansen):
    targets = targets_of(jansen)
    shipped = linkopt.load(MECHANISMS / "jansen_1dof.toml")
    angles = 2.0 * np.pi * np.arange(targets.count) / targets.count
    sol = linkopt.solve_fk_path(shipped, angles[:, None])
    assert targets.count == 24 and targets.closed
    foot = linkopt.named_points(shipped, sol.state)["foot"]
    np.testing.assert_allclose(targets.values, foot, rtol=0, atol=1e-9)
    stride = np.ptp(foot[:, 0])
    assert targets.tolerance <= 0.005 * stride + 1e-12


@pytest.mark.parametrize(
    ("name", "target"),
    [
        ("rssr.toml", gen.RSSR_TARGET),
        ("spherical_four_bar.toml", gen.SPHERICAL_TARGET),
        ("jansen_foot_path.toml", gen.jansen_design(gen.jansen_joints(gen.JANSEN))),
    ],
)
def test_the_target_design_meets_its_targets_and_the_file_s_does_not(name, target):
    mech = linkopt.load(MECHANISMS / name)
    targets = targets_of(mech)
    met = score_design(mech, targets, target, steps=120)
    assert met.rms < 1e-6 * np.ptp(targets.values) and met.feasible
    report = sweep_cycle(mech, target, targets, steps=240)
    assert report.defect is None and report.in_order
    start = score_design(mech, targets, steps=120)
    assert start.max_distance > 3 * targets.tolerance  # the synthesis has work to do
