"""Continuous-path synthesis of planar arms (paper 002): closed-form geometry,
swept-area bounds, the dense verifier, task-file errors, synthesis optimality, the
discretised comparison and the exported mechanism file."""

from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest
import scipy.optimize

import linkopt
from linkopt._arms.trace import geometry as geo
from linkopt._arms.trace.discrete import compare
from linkopt._arms.trace.export import mechanism_text, result_dict
from linkopt._arms.trace.swept import DIRS, app_support, over_support, signed_distance
from linkopt._arms.trace.synthesis import (
    TraceResult,
    TraceSettings,
    build_problem,
    initial_guess,
    synthesize,
)
from linkopt._arms.trace.task import load_task, loads_task
from linkopt._arms.trace.verify import PlanarArm, critical_states, verify
from linkopt._errors import MechanismFileError

ROOT = Path(__file__).resolve().parent.parent

HEAD = '[task]\nname = "t"\nlink_diameter = 0.02\n'
LINE = '[[primitives]]\ntype = "line"\nstart = [0.3, -0.1]\nend = [0.3, 0.1]\n'
ARC = (
    '[[primitives]]\ntype = "arc"\nstart = [0.3, 0.1]\nend = [0.2, 0.2]\n'
    'center = [0.2, 0.1]\ndirection = "ccw"\n'
)
FAR_OBSTACLE = "[[obstacles]]\ncenter = [-0.3, 0.3]\nradius = 0.03\n"
BASE = "[[base_regions]]\nmin = [-0.05, -0.05]\nmax = [0.05, 0.05]\n"
SMALL = HEAD + LINE + ARC + FAR_OBSTACLE + BASE


def _primitives():
    text = (
        HEAD
        + LINE
        + ARC
        + (
            '[[primitives]]\ntype = "arc"\nstart = [0.2, 0.2]\nend = [0.1, 0.1]\n'
            'center = [0.2, 0.1]\ndirection = "cw"\n'
            '[[primitives]]\ntype = "circle"\ncenter = [0.1, 0.0]\nradius = 0.1\n'
            'start = [0.1, 0.1]\ndirection = "cw"\n'
        )
    )
    return loads_task(text, "prims.toml").primitives


# --- closed-form geometry -------------------------------------------------------------


def test_two_link_reachable_space_is_the_annulus_of_eq_2():
    rng = np.random.default_rng(0)
    for a, b in [(0.3, 0.2), (0.2, 0.35), (0.25, 0.25)]:
        origin = rng.normal(size=2)
        q = rng.uniform(-np.pi, np.pi, size=(20000, 2))
        tips = np.asarray(
            geo.forward(jnp.asarray(origin), jnp.array([a, b]), jnp.asarray(q))
        )[:, -1]
        d = np.linalg.norm(tips - origin, axis=1)
        assert d.min() >= abs(a - b) - 1e-12 and d.max() <= a + b + 1e-12
        assert d.min() < abs(a - b) + 2e-3 and d.max() > a + b - 2e-3
        p = origin + rng.uniform(-1.2, 1.2, size=(400, 2)) * (a + b)
        inside = np.asarray(geo.reachable(jnp.asarray(origin), a, b, jnp.asarray(p)))
        for sigma in (1, -1):
            elbow = np.asarray(
                geo.ik_elbow(jnp.asarray(origin), a, b, jnp.asarray(p), sigma)
            )
            closes = np.isclose(np.linalg.norm(elbow - origin, axis=1), a, atol=1e-9)
            closes &= np.isclose(np.linalg.norm(p - elbow, axis=1), b, atol=1e-9)
            np.testing.assert_array_equal(closes, inside)
            side = np.asarray(
                geo.cross(jnp.asarray(p - origin), jnp.asarray(elbow - origin))
            )
            assert np.all(np.sign(side[inside]) == sigma)


def test_joint_angles_and_forward_kinematics_round_trip():
    rng = np.random.default_rng(1)
    q = rng.uniform(-3.0, 3.0, size=(50, 3))
    lengths = jnp.array([0.4, 0.3, 0.2])
    states = geo.forward(jnp.array([0.1, -0.2]), lengths, jnp.asarray(q))
    np.testing.assert_allclose(np.asarray(geo.joint_angles(states)), q, atol=1e-12)


@pytest.mark.parametrize("index", range(4), ids=["line", "arc_ccw", "arc_cw", "circle"])
def test_critical_points_match_brute_force_sampling(index):
    prim = _primitives()[index]
    dense = np.asarray(geo.points(prim, jnp.linspace(0.0, 1.0, 50001)))
    rng = np.random.default_rng(index)
    origins = np.concatenate(
        [rng.uniform(-0.4, 0.7, size=(25, 2)), [prim.center + [0.01, 0.02]]]
    )
    for origin in origins:
        d = np.linalg.norm(dense - origin, axis=1)
        cp = geo.critical_points(prim, jnp.asarray(origin))
        dmin, dmax = (
            float(np.linalg.norm(np.asarray(cp[k]) - origin))
            for k in ("closest", "farthest")
        )
        assert dmin == pytest.approx(d.min(), abs=1e-8)
        assert dmax == pytest.approx(d.max(), abs=1e-8)
        for k in ("closest", "farthest"):  # the point itself lies on the primitive
            assert np.min(np.linalg.norm(dense - np.asarray(cp[k]), axis=1)) < 1e-5


@pytest.mark.parametrize("offset", [0.0, 1e-16, 3e-8])
def test_circle_seen_from_its_centre_has_every_point_at_the_radius(offset):
    """Regression: a bias in the norm's epsilon turned (s - c)/|s - c| into a short
    vector near the centre, so closest = farthest = the centre and the NLP accepted a
    0.08 m arm for a 0.2 m circle (caught by the verifier)."""
    circle = _primitives()[3]
    dmin, dmax = geo.distance_range(circle, jnp.asarray(circle.center + offset))
    assert float(dmin) == pytest.approx(0.1, abs=1e-7) and float(dmax) == pytest.approx(
        0.1, abs=1e-7
    )


@pytest.mark.parametrize("index", range(4), ids=["line", "arc_ccw", "arc_cw", "circle"])
def test_support_function_matches_sampled_maximum(index):
    prim = _primitives()[index]
    dense = np.asarray(geo.points(prim, jnp.linspace(0.0, 1.0, 100001)))
    np.testing.assert_allclose(
        np.asarray(geo.support(prim, jnp.asarray(DIRS))),
        (dense @ DIRS.T).max(0),
        atol=1e-9,
    )


def test_swept_area_over_approximation_contains_the_true_swept_area():
    task = loads_task(SMALL, "small.toml")
    design = PlanarArm(np.array([0.0, 0.0]), np.array([0.2, 0.22]), np.zeros(0), 1)
    check = verify(task, design)
    ang = np.linspace(0, 2 * np.pi, 720, endpoint=False)
    fine = np.stack([np.cos(ang), np.sin(ang)], -1)
    for j, prim in enumerate(task.primitives):
        states = check.segments[2 * j].states
        s = np.linspace(0, 1, 5)[None, :, None]
        link_points = np.concatenate(
            [
                states[:, k, None] + s * (states[:, k + 1, None] - states[:, k, None])
                for k in range(2)
            ],
            1,
        )
        h = np.maximum(
            np.asarray(geo.support(prim, jnp.asarray(fine))),
            fine @ design.base + design.lengths[0],
        )
        assert (link_points.reshape(-1, 2) @ fine.T - h).max() <= 1e-12
        # the sampled-direction distance used in the NLP is a lower bound: <= 0 inside
        (sv,) = over_support(prim, jnp.asarray(design.base), design.lengths[0])
        assert (
            float(jnp.max(signed_distance(jnp.asarray(link_points.reshape(-1, 2)), sv)))
            <= 1e-12
        )
        sv1, sv2 = app_support(
            prim, jnp.asarray(design.base), *design.lengths, 1, temp=1e-3
        )
        assert (
            float(signed_distance(jnp.asarray(design.base), sv1)) <= 0
        )  # SV_1^app holds s_{n-1}


# --- verification ---------------------------------------------------------------------


def _clip_task(obstacle):
    text = (
        HEAD
        + LINE
        + f"[[obstacles]]\ncenter = [{obstacle[0]!r}, {obstacle[1]!r}]\n"
        + f"radius = {obstacle[2]!r}\n"
    )
    return loads_task(text, "clip.toml")


def test_verifier_rejects_design_that_clips_an_obstacle_only_between_critical_points():
    design = PlanarArm(np.array([0.0, 0.0]), np.array([0.2, 0.22]), np.zeros(0), 1)
    probe = _clip_task((5.0, 5.0, 0.01))
    # on the forearm near its tip, three quarters along the line (t = 0.75): between the
    # closest point (t = 0.5) and the final point
    state = np.asarray(
        geo.arm_states(
            jnp.asarray(design.base),
            jnp.asarray(design.lengths),
            0.0,
            geo.points(probe.primitives[0], jnp.array([0.75])),
            1,
        )
    )[0]
    center = state[1] + 0.95 * (state[2] - state[1])
    task = _clip_task((float(center[0]), float(center[1]), 0.008))
    for states in critical_states(task, design):  # all critical states are clear
        d = np.asarray(
            geo.segment_distance(
                jnp.asarray(center),
                jnp.asarray(states[:, :-1]),
                jnp.asarray(states[:, 1:]),
            )
        )
        assert d.min() > 0.008 + task.link_diameter / 2
    check = verify(task, design)
    assert not check.passed
    assert any("primitives[0]" in f and "obstacles[0]" in f for f in check.failures)
    assert verify(
        probe, design
    ).passed  # the same motion with the obstacle far away passes


def test_verifier_rejects_a_three_link_transition_through_an_obstacle():
    """The proximal link swings from -0.6 to 0.6 rad at the transition point and sweeps
    over an obstacle on the x-axis that no primitive state touches."""
    lines = (
        '[[primitives]]\ntype = "line"\nstart = [0.3, -0.1]\nend = [0.3, 0.0]\n'
        '[[primitives]]\ntype = "line"\nstart = [0.3, 0.0]\nend = [0.35, 0.05]\n'
    )
    obstacle = "[[obstacles]]\ncenter = [{x}, 0.0]\nradius = 0.01\n"
    design = PlanarArm(
        np.array([0.0, 0.0]), np.array([0.2, 0.15, 0.15]), np.array([-0.6, 0.6]), 1
    )
    blocked = loads_task(HEAD + lines + obstacle.format(x=0.1), "swing.toml")
    for states in critical_states(blocked, design):
        d = np.asarray(
            geo.segment_distance(
                jnp.array([0.1, 0.0]),
                jnp.asarray(states[:, :-1]),
                jnp.asarray(states[:, 1:]),
            )
        )
        assert d.min() > 0.01 + blocked.link_diameter / 2
    failures = verify(blocked, design).failures
    assert failures and all(
        f.startswith("transition 0->1: link 1 clips obstacles[0]") for f in failures
    )
    assert verify(
        loads_task(HEAD + lines + obstacle.format(x=-0.5), "swing.toml"), design
    ).passed


def test_verifier_rejects_unreachable_and_self_colliding_designs():
    task = loads_task(HEAD + LINE, "reach.toml")
    short = PlanarArm(np.array([0.0, 0.0]), np.array([0.15, 0.15]), np.zeros(0), 1)
    assert any("annulus" in f for f in verify(task, short).failures)
    folded = PlanarArm(
        np.array([0.0, 0.0]), np.array([0.5, 0.201]), np.zeros(0), 1
    )  # EE passes near link 1
    assert verify(task, folded).min_reach_margin > 0
    assert any("eqs. 8-9" in f for f in verify(task, folded).failures)


# --- task files -----------------------------------------------------------------------


@pytest.mark.parametrize(
    "text, field, words",
    [
        (HEAD + "[[primitives]\n", "", "invalid TOML"),
        (LINE, "task", "missing required table"),
        (
            HEAD + LINE.replace('"line"', '"spline"'),
            "primitives[0].type",
            "unknown primitive type",
        ),
        (HEAD + LINE + LINE, "primitives[1].start", "must be connected"),
        (
            HEAD + ARC.replace("end = [0.2, 0.2]", "end = [0.2, 0.25]"),
            "primitives[0].end",
            "distance",
        ),
        (HEAD + ARC.replace('"ccw"', '"clockwise"'), "primitives[0].direction", "cw"),
        (
            HEAD + LINE.replace("end = [0.3, 0.1]", "end = [0.3]"),
            "primitives[0].end",
            "2 finite numbers",
        ),
        (
            HEAD + LINE + "[[obstacles]]\ncenter = [0.0, 0.0]\nradius = -1.0\n",
            "obstacles[0].radius",
            "positive",
        ),
        (
            HEAD + ARC + "[[obstacles]]\ncenter = [0.2, 0.12]\nradius = 0.01\n",
            "obstacles[0].center",
            "inside the circle",
        ),
        (
            HEAD + LINE + "[[base_regions]]\nmin = [0.0, 0.0]\nmax = [-1.0, 1.0]\n",
            "base_regions[0].max",
            "max > min",
        ),
        (
            HEAD + LINE.replace('type = "line"', 'type = "line"\ncolour = "red"'),
            "primitives[0].colour",
            "unknown field",
        ),
        (
            HEAD.replace("link_diameter = 0.02", "link_diameter = 0"),
            "task.link_diameter",
            "positive",
        ),
        (HEAD, "primitives", "at least one"),
    ],
)
def test_bad_task_files_give_one_line_naming_file_and_field(text, field, words):
    with pytest.raises(MechanismFileError) as err:
        loads_task(text, "bad.toml")
    message = str(err.value)
    assert (
        message.startswith(f"bad.toml: {field}")
        and words in message
        and "\n" not in message
    )


def test_non_utf8_task_file_is_one_line_error(tmp_path):
    path = tmp_path / "latin1.toml"
    path.write_bytes(
        (HEAD + LINE).replace("[task]", "# caf\xe9\n[task]").encode("latin-1")
    )
    with pytest.raises(
        MechanismFileError, match="latin1.toml: cannot read file"
    ) as err:
        load_task(path)
    assert "\n" not in str(err.value)


def test_shipped_tasks_match_the_paper_description():
    rose, wipe, clean = (
        load_task(ROOT / "tasks" / f"{n}.toml")
        for n in ("rose", "wipe_table", "clean_table")
    )
    assert len(rose.primitives) == 7 and {p.kind for p in rose.primitives} == {
        "line",
        "arc",
        "circle",
    }
    assert len(rose.obstacles) == 3 and len(rose.base_regions) == 1
    assert [p.kind for p in wipe.primitives] == ["line"] * 3 and len(
        wipe.obstacles
    ) == 2
    assert (
        len(clean.primitives) == 5
        and {p.kind for p in clean.primitives} == {"line", "arc"}
        and len(clean.obstacles) == 2
    )


# --- synthesis ------------------------------------------------------------------------


@pytest.fixture(scope="module")
def small_result():
    task = loads_task(SMALL, "small.toml")
    return synthesize(
        task, seed=0, settings=TraceSettings(restarts=2, links=(2,), swept=("over",))
    )


def test_synthesis_finds_the_shortest_two_link_arm(small_result):
    """Without active obstacles the optimum of eq. 1 is min over the base rectangle of
    the farthest path distance (+ the reach margin): a + b must reach it and a = b
    suffices."""
    task, result = small_result.task, small_result
    assert result.success and result.verification.passed and result.swept == "over"
    pts = np.concatenate(
        [np.asarray(geo.points(p, jnp.linspace(0, 1, 2001))) for p in task.primitives]
    )

    def far(b):
        return np.sqrt(((np.atleast_2d(b)[:, None] - pts[None]) ** 2).sum(-1)).max(1)

    g = np.linspace(-0.05, 0.05, 41)
    bases = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    start = bases[far(bases).argmin()]

    def clipped(b):  # farthest distance is convex in the base
        return far(np.clip(b, -0.05, 0.05))[0]

    ref = scipy.optimize.minimize(
        clipped, start, method="Nelder-Mead", options={"xatol": 1e-9, "fatol": 1e-12}
    )
    best = ref.fun + TraceSettings().reach_margin * task.scale
    assert result.design.lengths.sum() == pytest.approx(best, rel=1e-4, abs=1e-6)


def test_constraint_jacobian_matches_finite_differences():
    task = loads_task(SMALL.replace("[-0.3, 0.3]", "[0.1, 0.35]"), "small.toml")
    problem = build_problem(task, 3, "app", TraceSettings())
    x = initial_guess(task, 3, 0, np.random.default_rng(3))
    jac = np.asarray(problem.jac(x, 1))
    fd = np.stack(
        [
            (np.asarray(problem.g(x + e, 1)) - np.asarray(problem.g(x - e, 1))) / 2e-6
            for e in np.eye(len(x)) * 1e-6
        ],
        axis=1,
    )
    np.testing.assert_allclose(jac, fd, atol=2e-5)


def test_exported_arm_is_a_mechanism_whose_fk_retraces_the_states(small_result):
    mech = linkopt.loads(mechanism_text(small_result), "arm.toml")
    seg = small_result.verification.segments[0]
    rest = seg.angles[0]
    for k in (0, len(seg.angles) // 2, -1):
        sol = linkopt.solve_fk(
            mech, jnp.asarray(np.angle(np.exp(1j * (seg.angles[k] - rest))))
        )
        assert bool(sol.converged)
        tip = np.asarray(linkopt.point_positions(mech, sol.state))[0]
        np.testing.assert_allclose(tip[:2], seg.states[k, -1], atol=1e-8)
    payload = result_dict(small_result)
    assert payload["verification"]["passed"] and payload["n_links"] == 2


def test_three_link_export_loads_with_a_shoulder_angle_output():
    task = loads_task(SMALL, "small.toml")
    design = PlanarArm(
        np.array([0.0, 0.0]), np.array([0.1, 0.15, 0.15]), np.array([0.3, 0.5]), -1
    )
    result = TraceResult(task, design, verify(task, design), "app", 0.0)
    mech = linkopt.loads(mechanism_text(result), "arm3.toml")
    assert list(mech.output_names) == ["x", "y", "shoulder_angle"]


# --- discretised comparison -----------------------------------------------------------


def test_discretised_design_misses_the_curve_between_its_points():
    """A circle seen from outside: a design whose outer radius just reaches the farthest
    of 25 sampled points leaves the true farthest point out by a closed-form amount."""
    task = loads_task(
        HEAD + '[[primitives]]\ntype = "circle"\ncenter = [0.3, 0.0]\nradius = 0.1\n'
        'start = [0.38, 0.06]\ndirection = "ccw"\n',
        "circle.toml",
    )
    from linkopt._arms.trace.discrete import equidistant_points

    pts = equidistant_points(task, 25)
    reach = np.linalg.norm(pts, axis=1).max()
    design = PlanarArm(
        np.array([0.0, 0.0]), np.array([reach / 2, reach / 2]), np.zeros(0), 1
    )
    cmp = compare(task, design)
    assert (
        cmp.excursion == pytest.approx(0.4 - reach, abs=1e-6) and cmp.excursion > 1e-4
    )
    assert 0 < cmp.fraction_outside < 0.2
    assert not cmp.verification.passed


def test_too_many_primitives_are_refused():
    lines = "".join(
        '[[primitives]]\ntype = "line"\n'
        f"start = [0.3, {0.1 * (k % 2)}]\nend = [0.3, {0.1 * ((k + 1) % 2)}]\n"
        for k in range(101)
    )
    with pytest.raises(MechanismFileError, match="primitives: 101 primitives exceed"):
        loads_task(HEAD + lines, "many.toml")


def test_unknown_search_settings_are_input_errors():
    from linkopt import InputError
    from linkopt._arms.trace.swept import swept_support
    from linkopt._arms.trace.synthesis import TraceSettings, synthesize

    task = loads_task(SMALL, "small.toml")
    with pytest.raises(InputError, match="swept: unknown swept-area bound 'hull'"):
        swept_support("hull", task.primitives[0], None, 0.1, 0.1, 1)
    with pytest.raises(InputError, match="settings: swept"):
        synthesize(task, settings=TraceSettings(swept=("hull",)))
    with pytest.raises(InputError, match="settings: links"):
        synthesize(task, settings=TraceSettings(links=(4,)))
