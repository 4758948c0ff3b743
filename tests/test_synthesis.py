"""Synthesis (issue 41) on the crank-rocker four-bar: the swept cycle against closed
forms (the coupler curve by circle intersection, Freudenstein's equation), the
tracked σ_min against the exact one, the partial gradient against finite
differences, and short path, function and motion syntheses."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import linkopt
from linkopt._files.synthesis import build
from linkopt._synth import objective
from linkopt._synth.run import finish, four_bar_summary
from linkopt.synthesis import load_targets, score, synthesize, verify

ROOT = Path(__file__).resolve().parents[1]
FILE = ROOT / "mechanisms" / "four_bar_path.toml"
STEPS = 72  # a 5° sweep keeps the compiled programs small
DESIGN = np.array([63.0, 66.0, 47.0])  # (ground_d, pin_x, pin_y): the targets' design


@pytest.fixture(scope="module")
def mech():
    return linkopt.load(FILE)


def _rotate(v, angle):
    c, s = np.cos(angle), np.sin(angle)
    return np.stack([c * v[..., 0] - s * v[..., 1], s * v[..., 0] + c * v[..., 1]], -1)


def _coupler_curve(mech, design, turn):
    """The coupler point over crank angles ``turn`` by circle intersection, on the
    rest pose's branch; and the rocker's angle from its rest angle."""
    geom = linkopt.geometry(mech, design)
    scale = mech.length_scale
    anchors = np.asarray(geom.anchors)[:, :2] * scale
    point = np.asarray(geom.points)[0, :2] * scale
    a, b0, c0, d = (anchors[mech.joint_names.index(n)] for n in "ABCD")
    coupler, rocker = np.linalg.norm(c0 - b0), np.linalg.norm(c0 - d)
    b = a + _rotate(b0 - a, turn)
    gap = d - b
    far = np.linalg.norm(gap, axis=1)
    along = (coupler**2 - rocker**2 + far**2) / (2 * far)
    height = np.sqrt(coupler**2 - along**2)
    unit = gap / far[:, None]
    normal = np.stack([-unit[:, 1], unit[:, 0]], 1)
    u, v = d - b0, c0 - b0
    side = np.sign(u[0] * v[1] - u[1] * v[0])  # the rest pose's branch
    c = b + along[:, None] * unit + side * height[:, None] * normal
    spin = np.arctan2(*(c - b).T[::-1]) - np.arctan2(*(c0 - b0)[::-1])
    curve = b + _rotate(np.broadcast_to(point - b0, b.shape), spin)
    swing = np.arctan2(*(c - d).T[::-1]) - np.arctan2(*(c0 - d)[::-1])
    return curve, (swing + np.pi) % (2 * np.pi) - np.pi, (a, b0, c0, d)


def _targets(mech, kind, name, values, motors=None, closed=False, tolerance=0.5):
    return build(mech.source, "test", kind, name, values, motors, closed, tolerance)


def test_the_traced_curve_is_the_closed_form_coupler_curve(mech):
    targets = load_targets(mech)
    result = score(mech, targets, DESIGN, steps=STEPS)
    assert result.solved.all()
    turn = result.motors[:, 0]
    curve, _, _ = _coupler_curve(mech, DESIGN, turn)
    np.testing.assert_allclose(result.traced[:, :2], curve, rtol=0, atol=1e-9)
    np.testing.assert_allclose(result.traced[:, 2], 0.0, atol=1e-9)
    # the targets are that design's curve at 60° steps, rounded to 1e-3
    assert result.max_distance < 2e-3
    assert result.feasible


def test_the_tracked_sigma_min_is_the_exact_one_to_a_rayleigh_bound(mech):
    """One inverse iteration a row, the vector carried along the cycle: the Rayleigh
    estimate is never below the exact σ_min and within 1e-3 of it (5° rows)."""
    targets = load_targets(mech)
    problem = objective.Problem(targets, objective.plan(mech, targets, STEPS))
    from linkopt._design.evaluation import alpha_minus

    scored = objective.score(mech, problem, DESIGN[None], alpha_minus(mech))
    states = np.asarray(scored.states)[0]
    exact = np.asarray(linkopt.singular_values(mech, states, design=DESIGN))[:, 0]
    least = float(scored.least_sigma[0])
    assert exact.min() * (1 - 1e-12) <= least <= exact.min() * (1 + 1e-3)


def test_function_generation_follows_freudensteins_equation(mech):
    turn = np.linspace(0.0, 2 * np.pi, 7)[:-1]
    _, swing, (a, b0, c0, d) = _coupler_curve(mech, DESIGN, turn)
    targets = _targets(mech, "function", "rocker", swing, turn[:, None], tolerance=1e-3)
    result = score(mech, targets, DESIGN, steps=STEPS)
    assert result.max_distance < 1e-9  # timing: each pair read at its own row
    # Freudenstein: K1 cos ψ - K2 cos φ + K3 = cos(φ - ψ) along the whole cycle
    crank, coupler, rocker = (np.linalg.norm(v) for v in (b0 - a, c0 - b0, c0 - d))
    ground = np.linalg.norm(d - a)
    phi = result.motors[:, 0] + np.arctan2(*(b0 - a)[::-1])
    psi = result.traced + np.arctan2(*(c0 - d)[::-1])
    k1, k2 = ground / crank, ground / rocker
    k3 = (crank**2 - coupler**2 + rocker**2 + ground**2) / (2 * crank * rocker)
    residual = k1 * np.cos(psi) - k2 * np.cos(phi) + k3 - np.cos(phi - psi)
    assert np.max(np.abs(residual)) < 1e-9
    # another design misses the same pairs
    assert score(mech, targets, mech.design.p0, steps=STEPS).max_distance > 1e-3


def test_motion_generation_scores_the_body_pose(mech):
    path = load_targets(mech)
    problem = objective.Problem(path, objective.plan(mech, path, STEPS))
    from linkopt._design.evaluation import alpha_minus

    scored = objective.score(mech, problem, DESIGN[None], alpha_minus(mech))
    body = mech.body_names.index("coupler")
    rows = [0, 12, 24, 40]
    poses = np.asarray(scored.states)[0][rows, 7 * body : 7 * body + 7].copy()
    poses[:, :3] *= mech.length_scale
    targets = _targets(mech, "motion", "coupler", poses, closed=True)
    result = score(mech, targets, DESIGN, steps=STEPS)
    assert result.max_distance < 1e-9
    np.testing.assert_array_equal(result.rows, rows)
    assert score(mech, targets, mech.design.p0, steps=STEPS).max_distance > 0.1


def test_the_partial_gradient_of_a_timed_path_matches_finite_differences(mech):
    turn = np.array([0.0, 1.5, 3.0, 4.5])
    curve, _, _ = _coupler_curve(mech, DESIGN, turn)
    values = np.column_stack([curve, np.zeros(4)])
    targets = _targets(mech, "path", "coupler_point", values, turn[:, None])
    problem = objective.Problem(targets, objective.plan(mech, targets, STEPS))
    from linkopt._design.evaluation import alpha_minus

    alpha = alpha_minus(mech)
    design = mech.design.p0
    step = 1e-4
    # the design, then each parameter moved up, then down: one batch, one program
    moves = np.concatenate([np.zeros((1, 3)), step * np.eye(3), -step * np.eye(3)])
    designs = design + moves
    scored = objective.score(mech, problem, designs, alpha)
    assert float(scored.singularity[0]) == 0.0
    gradient = objective.gradients(mech, problem, designs, scored, alpha)[0]
    path = np.asarray(scored.path)
    for i in range(mech.design.size):
        up, down = path[1 + i], path[4 + i]
        assert gradient[i] == pytest.approx((up - down) / (2 * step), rel=1e-4)


def test_a_short_synthesis_lowers_the_rms_and_keeps_the_cycle_clear(mech):
    near = np.array([61.5, 65.0, 50.0])
    # six points, as the file's targets: the same compiled single-design score
    turn = np.linspace(0.0, 2 * np.pi, 7)[:-1]
    curve, _, _ = _coupler_curve(mech, near, turn)
    targets = _targets(mech, "path", "coupler_point", curve, closed=True, tolerance=1.0)
    start = score(mech, targets, steps=STEPS)
    # four particles, as test_cli_synthesize.py's and test_synthesis_outputs.py's runs
    # of the file's six targets: the same compiled swarm score and gradient
    settings = linkopt.OptimizerSettings(particles=4, iterations=3, spread=0.1, seed=0)
    seen = []
    result = synthesize(mech, targets, settings, steps=STEPS, progress=seen.append)
    assert len(result.history) == len(seen) <= 3
    assert result.rms < start.rms
    assert result.solved.all() and result.parts["singularity"] == 0.0
    assert result.least_sigma > 2.0 / result.alpha_minus  # f_sing below α₋
    assert np.all(result.design >= mech.design.lower)
    assert np.all(result.design <= mech.design.upper)
    again = finish(mech, objective.Problem(targets, result.plan), result.design,
                   result.alpha_minus)  # fmt: skip
    assert again.rms == pytest.approx(result.rms, rel=1e-12)
    report = verify(mech, result)
    assert report.solved.all() and report.defect is None  # defect-free
    # the objective's σ_min is a Rayleigh estimate, within 1e-3 above the exact
    assert report.least_sigma >= result.least_sigma * (1 - 1e-3)
    # the transmission angle over the swept rows against the closed form over the
    # full turn (Norton): never below it, and within the 5° rows' sampling of it
    worst = four_bar_summary(mech, result.design)["transmission_worst_deg"]
    assert worst - 1e-9 <= result.least_transmission_deg <= worst + 1.0
    assert result.least_transmission_deg >= targets.min_transmission_deg
    assert result.parts["order"] == 0.0 and result.parts["transmission"] == 0.0


def test_a_short_function_synthesis_lowers_the_miss(mech):
    # six pairs, as Freudenstein's test above: the same compiled single-design score
    turn = np.linspace(0.0, 2 * np.pi, 7)[:-1]
    _, swing, _ = _coupler_curve(mech, np.array([61.5, 65.0, 50.0]), turn)
    targets = _targets(mech, "function", "rocker", swing, turn[:, None], tolerance=0.01)
    start = score(mech, targets, steps=STEPS)
    settings = linkopt.OptimizerSettings(particles=6, iterations=2, spread=0.1, seed=0)
    result = synthesize(mech, targets, settings, steps=STEPS)
    assert result.rms < start.rms
    assert result.solved.all() and result.parts["singularity"] == 0.0
    np.testing.assert_array_equal(result.rows, objective.plan(mech, targets, STEPS).at)


def test_a_closed_timed_crank_curve_goes_round_not_back(mech):
    rows = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    timing = np.array([[0.5], [2.0], [4.0]])
    targets = _targets(mech, "path", "coupler_point", rows, timing, closed=True)
    plan = objective.plan(mech, targets, 120)
    turn = plan.motors[:, 0]
    assert np.all(np.diff(turn) > 0)  # one way round
    assert turn[-1] == pytest.approx(turn[0] + 2 * np.pi)
    np.testing.assert_allclose(turn[plan.at], timing[:, 0])


def test_the_collision_part_is_the_weighted_term_over_every_fourth_row():
    from linkopt._engine.collision import collision_value

    mech = linkopt.load(ROOT / "mechanisms" / "four_bar_collision.toml")
    body = mech.body_names.index("coupler")
    rest = np.asarray(linkopt.rest_state(mech))[7 * body : 7 * body + 7].copy()
    rest[:3] *= mech.length_scale
    poses = np.array([rest, rest + [1.0, 0, 0, 0, 0, 0, 0]])
    targets = _targets(mech, "motion", "coupler", poses, tolerance=0.5)
    problem = objective.Problem(targets, objective.plan(mech, targets, STEPS))
    from linkopt._design.evaluation import alpha_minus

    design = mech.design.p0
    scored = objective.score(mech, problem, design[None], alpha_minus(mech))
    assert np.asarray(scored.solved).all()
    geom = linkopt.geometry(mech, design)
    states = np.asarray(scored.states)[0][:: objective.STRIDE]
    values = [float(collision_value(mech, geom, s)) for s in states]
    expected = mech.collision.weight * np.mean(values)
    assert float(scored.collision[0]) == pytest.approx(expected, rel=1e-9, abs=1e-15)
