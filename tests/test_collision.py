"""Link collisions (issue 30): capsule distances, the barrier, ``[collision]``, and
their use in ``evaluate`` and ``verify``.

* the segment distance is exact: it matches closed forms (parallel, crossing,
  end-to-end, point) and is never above, and within sampling error of, a dense
  brute-force minimum on random segment pairs of every kind;
* its gradient matches central finite differences, and is finite (no NaN) for
  parallel, crossing and zero-length segments;
* the barrier is zero past the band, 1 at contact, and its value and slope are
  continuous at the band's edge;
* capsule ends follow their bodies: in a solved state they are the joints' positions;
* the loader's ``[collision]`` defaults, pairs and refusals;
* a four-bar whose coupler sweeps through its ground link fails ``verify`` naming
  ground and coupler; the same four-bar with the coupler in another layer passes, with
  the clearance the layers' closed form gives;
* a file without ``[collision]`` evaluates and fingerprints as before.
"""

from __future__ import annotations

import dataclasses
import hashlib
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import linkopt
from linkopt._engine.collision import (
    barrier,
    capsule_ends,
    clearance,
    pair_names,
    segment_distance,
)
from linkopt._engine.geometry import geometry
from linkopt._engine.links import CLEARANCE_FRACTION, default_pairs
from linkopt._engine.model import digest

DATA = Path(__file__).parent / "data"
ROOT = Path(__file__).resolve().parents[1]
COLLIDING = DATA / "four_bar_collision.toml"
LAYERED = DATA / "four_bar_layers.toml"
FOUR_BAR = ROOT / "mechanisms" / "four_bar.toml"

distance = jax.jit(segment_distance)


def brute_force(p1, q1, p2, q2, count: int = 1501) -> float:
    """Least distance between ``count`` samples of the first segment and the second
    segment (each sample's exact distance to it), in numpy."""
    s = np.linspace(0.0, 1.0, count)[:, None]
    points = p1 + s * (q1 - p1)
    d = q2 - p2
    length2 = d @ d
    t = np.zeros(count) if length2 == 0 else (points - p2) @ d / length2
    closest = p2 + np.clip(t, 0.0, 1.0)[:, None] * d
    return float(np.min(np.linalg.norm(points - closest, axis=1)))


def exact(p1, q1, p2, q2) -> float:
    return float(
        distance(*(jnp.asarray(v, dtype=jnp.float64) for v in (p1, q1, p2, q2)))
    )


# --- closed forms -------------------------------------------------------------------


def test_parallel_segments_overlapping_and_apart():
    x, y = np.eye(3)[0], np.eye(3)[1]
    assert exact(0 * x, x, y, x + y) == pytest.approx(1.0, abs=1e-15)
    assert exact(0 * x, x, 0.5 * x + 2 * y, 3 * x + 2 * y) == pytest.approx(2.0)
    # parallel, no overlap along the line: end to end
    assert exact(0 * x, x, 2 * x + y, 3 * x + y) == pytest.approx(np.sqrt(2.0))
    # antiparallel
    assert exact(0 * x, x, x + y, y) == pytest.approx(1.0)


def test_collinear_end_to_end_and_touching():
    x = np.eye(3)[0]
    assert exact(0 * x, x, 3 * x, 2 * x) == pytest.approx(1.0)
    assert exact(0 * x, x, x, 2 * x) == 0.0


def test_crossing_and_skew_segments():
    x, y, z = np.eye(3)
    assert exact(-x, x, -y, y) == 0.0
    assert exact(-x, x, -y + 0.25 * z, y + 0.25 * z) == pytest.approx(0.25)
    # skew, closest points at the ends of one segment
    assert exact(-x, x, 2 * x - y + z, 2 * x + y + z) == pytest.approx(np.sqrt(2.0))


def test_degenerate_segments_are_points():
    x, y = np.eye(3)[0], np.eye(3)[1]
    assert exact(y, y, -x, x) == pytest.approx(1.0)
    assert exact(-x, x, 2 * x + y, 2 * x + y) == pytest.approx(np.sqrt(2.0))
    assert exact(y, y, 3 * y, 3 * y) == pytest.approx(2.0)
    assert exact(y, y, y, y) == 0.0


# --- random pairs against brute force ------------------------------------------------

coordinate = st.floats(-3.0, 3.0, allow_nan=False, allow_infinity=False)
vector = st.tuples(coordinate, coordinate, coordinate).map(np.array)


@st.composite
def segment_pairs(draw):
    """Two segments of one of the kinds: general, parallel, crossing, end to end,
    with a zero-length one."""
    kind = draw(st.sampled_from(["general", "parallel", "crossing", "end", "point"]))
    p1, q1, p2, q2 = draw(vector), draw(vector), draw(vector), draw(vector)
    if kind == "parallel":
        q2 = p2 + draw(st.floats(-2.0, 2.0)) * (q1 - p1)
    elif kind == "crossing":  # both through one point
        s, t = draw(st.floats(0.0, 1.0)), draw(st.floats(0.0, 1.0))
        meet = p1 + s * (q1 - p1)
        p2 = meet - t * (q2 - p2)
        q2 = p2 + (q2 - p2) if t == 0 else meet + (1 - t) / t * (meet - p2)
    elif kind == "end":
        p2 = q1 + draw(st.floats(0.0, 0.5)) * (q1 - p1)
    elif kind == "point":
        q2 = p2
        if draw(st.booleans()):
            q1 = p1
    return p1, q1, p2, q2


@settings(max_examples=150, deadline=None)
@given(segment_pairs())
def test_distance_is_the_minimum_over_the_segments(pair):
    value = exact(*pair)
    sampled = brute_force(*pair)
    lengths = max(np.linalg.norm(pair[1] - pair[0]), np.linalg.norm(pair[3] - pair[2]))
    assert np.isfinite(value) and value >= 0.0
    assert value <= sampled + 1e-9  # no sampled pair of points is closer
    assert sampled - value <= 2e-3 * max(lengths, 1.0)  # and sampling finds it


def test_random_pairs_with_a_seed_against_brute_force():
    rng = np.random.default_rng(0)
    for _ in range(40):
        pair = rng.normal(size=(4, 3))
        assert exact(*pair) == pytest.approx(brute_force(*pair, 4001), abs=2e-4)


# --- gradients ----------------------------------------------------------------------


def _flat_distance(x):
    return segment_distance(x[0:3], x[3:6], x[6:9], x[9:12])


def test_gradient_matches_finite_differences():
    grad = jax.jit(jax.grad(_flat_distance))
    rng = np.random.default_rng(1)
    for _ in range(20):
        x = rng.normal(size=12)
        h = 1e-6
        fd = np.array(
            [
                (_flat_distance(x + h * e) - _flat_distance(x - h * e)) / (2 * h)
                for e in np.eye(12)
            ]
        )
        np.testing.assert_allclose(np.asarray(grad(x)), fd, atol=1e-6)


@pytest.mark.parametrize(
    "pair",
    [
        [[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]],  # parallel
        [[0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]],  # collinear
        [[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]],  # crossing: distance 0
        [[0, 1, 0], [0, 1, 0], [-1, 0, 0], [1, 0, 0]],  # a point
        [[0, 0, 0], [0, 0, 0], [0, 0, 0], [0, 0, 0]],  # two coincident points
        [[0, 0, 0], [1e-160, 0, 0], [0, 1, 0], [0, 1, 0]],  # almost a point
    ],
    ids=["parallel", "collinear", "crossing", "point", "coincident", "tiny"],
)
def test_gradient_is_finite_where_the_closest_pair_is_not_unique(pair):
    x = jnp.asarray(np.ravel(pair), dtype=jnp.float64)
    value, grad = jax.value_and_grad(_flat_distance)(x)
    assert np.isfinite(float(value))
    assert np.all(np.isfinite(np.asarray(grad)))


def test_crossing_segments_have_zero_distance_and_gradient_after_rounding():
    """Segments that cross at a point no float represents: the computed distance is
    0, not a rounding residue, and its gradient is zero, not a unit vector in an
    arbitrary direction."""
    x = jnp.array([0.1, 0.3, 0.0, 0.7, -0.2, 0.0, 0.2, -0.3, 0.0, 0.5, 0.9, 0.0])
    value, grad = jax.value_and_grad(_flat_distance)(x)
    assert float(value) == 0.0
    assert np.all(np.asarray(grad) == 0.0)


def test_parallel_gradient_moves_the_segments_apart():
    """Parallel segments a unit apart: the distance grows at unit rate when the second
    moves away along the normal."""
    x = jnp.array([0.0, 0, 0, 1, 0, 0, 0, 1, 0, 1, 1, 0])
    grad = np.asarray(jax.grad(_flat_distance)(x))
    assert grad[[7, 10]].sum() == pytest.approx(1.0)
    assert grad[[1, 4]].sum() == pytest.approx(-1.0)


# --- the barrier --------------------------------------------------------------------


def test_barrier_values():
    band = 0.3
    assert float(barrier(1.0, band)) == 0.0
    assert float(barrier(band, band)) == 0.0
    assert float(barrier(0.0, band)) == pytest.approx(1.0)
    assert float(barrier(-band, band)) == pytest.approx(4.0)
    inside = barrier(jnp.linspace(-1.0, band, 50), band)
    assert np.all(np.diff(np.asarray(inside)) < 0)  # grows towards and through contact


def test_barrier_is_c1_at_the_band_edge():
    band = 0.3
    slope = jax.grad(lambda g: barrier(g, band))
    for eps in (1e-3, 1e-5, 1e-7):
        below, above = band - eps, band + eps
        assert float(barrier(below, band)) == pytest.approx((eps / band) ** 2)
        assert float(barrier(above, band)) == 0.0
        assert abs(float(slope(below))) == pytest.approx(2 * eps / band**2)
        assert float(slope(above)) == 0.0
    assert float(slope(band)) == 0.0


# --- the file -----------------------------------------------------------------------


def _with(path: Path, extra: str, replace: tuple[str, str] | None = None) -> str:
    text = path.read_text()
    if replace:
        text = text.replace(*replace, 1)
    return text + "\n" + extra


def test_defaults_of_a_bare_collision_table():
    text = _with(FOUR_BAR, "[collision]\n")
    mech = linkopt.loads(text, "bare.toml")
    model = mech.collision
    thickness = 0.04 * mech.length_scale
    assert model.enabled
    assert model.clearance == pytest.approx(CLEARANCE_FRACTION * thickness)
    np.testing.assert_allclose(model.segment_radii, 0.5 * thickness)
    names = {pair_names(mech, q) for q in range(len(model.pairs))}
    assert names == {("ground", "coupler"), ("crank", "rocker")}
    assert np.all(model.body_offsets == 0.0)


def test_include_exclude_and_layers():
    mech = linkopt.load(LAYERED)
    model = mech.collision
    assert {pair_names(mech, q) for q in range(len(model.pairs))} == {
        ("ground", "coupler")
    }
    np.testing.assert_allclose(model.body_offsets[2], [0.0, 0.0, 8.0])
    assert model.segment_radii[model.segment_bodies == 2] == pytest.approx(1.5)
    text = _with(
        FOUR_BAR,
        '[collision]\ninclude = [["crank", "coupler"]]\n'
        'exclude = [["ground", "coupler"]]\n',
    )
    mech = linkopt.loads(text, "pairs.toml")
    pairs = {pair_names(mech, q) for q in range(len(mech.collision.pairs))}
    assert pairs == {("crank", "coupler"), ("crank", "rocker")}
    assert len(default_pairs(mech)) == 2


@pytest.mark.parametrize(
    "extra, field, words",
    [
        (
            "[collision]\nclearance = -1.0\n",
            "[collision].clearance",
            "expected a number",
        ),
        ("[collision]\nspeed = 1\n", "[collision].speed", "unknown field"),
        ("[collision]\nenable = 1\n", "[collision].enable", "true or false"),
        ('[collision]\ninclude = [["ground"]]\n', "[collision].include[0]", "pair"),
        ('[collision]\nexclude = [["ground", "ground"]]\n', "exclude[0]", "different"),
        (
            '[collision]\ninclude = [["ground", "nobody"]]\n',
            "include[0]",
            "unknown body",
        ),
        ("[collision]\nnormal = [0, 0, 0]\n", "[collision].normal", "zero-length"),
    ],
)
def test_refused_collision_settings(extra, field, words):
    with pytest.raises(linkopt.MechanismFileError) as err:
        linkopt.loads(_with(FOUR_BAR, extra), "bad.toml")
    message = str(err.value)
    assert "bad.toml" in message and field in message and words in message


def test_body_radius_is_checked_even_without_the_table():
    text = _with(FOUR_BAR, "", ('name = "crank"\n', 'name = "crank"\nradius = -2.0\n'))
    with pytest.raises(linkopt.MechanismFileError, match=r"bodies\[1\]\.radius"):
        linkopt.loads(text, "radius.toml")


def test_a_layer_needs_a_plane_normal():
    """A file whose revolute axes are not all parallel (one tilted; the mobility check
    is skipped): a layer is refused until the file gives [collision].normal."""
    text = _with(
        FOUR_BAR,
        "[collision]\n",
        ('name = "coupler"\n', 'name = "coupler"\nlayer = 5.0\n'),
    ).replace("axis = [0.0, 0.0, 1.0]", "axis = [0.0, 0.1, 1.0]", 1)
    with pytest.raises(linkopt.MechanismFileError, match=r"bodies\[2\]\.layer"):
        _build(text)
    mech = _build(text.replace("[collision]\n", "[collision]\nnormal = [0, 0, 2]\n"))
    np.testing.assert_allclose(mech.collision.body_offsets[2], [0.0, 0.0, 5.0])


def _build(text: str):
    from linkopt._files.fields import parse_toml
    from linkopt._files.loader import build

    return build(parse_toml(text, "layer.toml"), "layer.toml", check=False)


# --- geometry follows the state -----------------------------------------------------


def test_capsule_ends_follow_their_bodies():
    mech = linkopt.load(COLLIDING)
    solved = linkopt.solve_bk(mech, np.array([0.2]))
    geom = geometry(mech)
    ends = np.asarray(capsule_ends(mech, geom, jnp.asarray(solved.state)))
    joints = np.asarray(linkopt.joint_positions(mech, solved.state)) / mech.length_scale
    model = mech.collision
    for g, (a, b) in enumerate(model.segment_places):
        np.testing.assert_allclose(ends[g], joints[[a, b]], atol=1e-9)


def test_layers_keep_their_closed_form_clearance():
    """The coupler 8 mm above the ground, radii 1.5 and 1.6: where the coupler's
    projection crosses the ground link (the crank below it: the larger rocker angles)
    the clearance is 8 - 3.1 exactly, and nowhere less."""
    mech = linkopt.load(LAYERED)
    outputs = np.linspace(mech.output_min[0], mech.output_max[0], 7)[:, None]
    states = np.asarray(linkopt.solve_bk(mech, outputs).state)
    result = clearance(mech, states)
    assert np.all(result.minimum >= 4.9 - 1e-9)
    np.testing.assert_allclose(result.minimum[2:], 4.9, atol=1e-9)
    assert np.all(result.value == 0.0)
    one = clearance(mech, states[3:4])
    assert one.minimum[0] == result.minimum[3]


# --- verify and evaluate ------------------------------------------------------------


def test_a_coupler_through_the_ground_fails_verify_naming_the_pair():
    from linkopt._cli.verify import verification_payload
    from linkopt._design.verify import verify

    mech = linkopt.load(COLLIDING)
    result = verify(mech, resolution=9)
    assert result.coverage == 1.0 and result.max_f_sing < result.threshold
    assert not result.passed
    assert result.collision_pair == ("ground", "coupler")
    assert result.min_clearance < mech.collision.clearance
    payload = verification_payload(mech, result)
    assert payload["collision"]["pair"] == ["ground", "coupler"]
    assert set(payload["collision"]["cell"]) == {"rocker"}
    assert result.as_json()["collision_pair"] == ["ground", "coupler"]


def test_the_same_four_bar_in_two_layers_passes_verify():
    from linkopt._design.verify import verify

    result = verify(linkopt.load(LAYERED), resolution=9)
    assert result.passed
    assert result.min_clearance == pytest.approx(4.9)


def test_disabled_collision_changes_nothing_in_verify():
    from linkopt._design.verify import verify

    text = COLLIDING.read_text().replace("enable = true", "enable = false")
    result = verify(linkopt.loads(text, "off.toml"), resolution=9)
    assert result.passed and result.min_clearance is None
    assert "collision_pair" not in result.as_json()


def test_evaluate_reports_the_collision_term_pair_and_pose():
    from linkopt._cli.evaluation import evaluation_payload

    mech = linkopt.load(COLLIDING)
    entry = evaluation_payload(mech, linkopt.evaluate(mech))["collision"]
    assert entry["term"] > 0.0
    assert entry["pair"] == ["ground", "coupler"]
    assert entry["min_clearance"] < 0.0  # the coupler crosses the ground link
    assert entry["pose"]["sample"] in ("ik", "collision")
    assert set(entry["pose"]["motors"]) == {"crank"}


#: ``linkopt evaluate --json``'s keys for a file without [collision].
EVALUATE_KEYS = {
    "f_design",
    "at_bounds",
    "reach",
    "singularity",
    "regularizer",
    "alpha_minus",
    "rest_pose",
    "capped_samples",
    "samples",
}


def test_a_file_without_collision_evaluates_as_before():
    """No collision entry, and the same payload as the file with the table
    switched off (which checks nothing)."""
    from linkopt._cli.evaluation import evaluation_payload

    mech = linkopt.load(FOUR_BAR)
    assert mech.collision is None
    payload = evaluation_payload(mech, linkopt.evaluate(mech))
    assert set(payload) == EVALUATE_KEYS
    off = linkopt.loads(_with(FOUR_BAR, "[collision]\nenable = false\n"), "off.toml")
    assert evaluation_payload(off, linkopt.evaluate(off)) == payload


class _Recorder:
    def __init__(self):
        self.parts: list[bytes] = []
        self.sink = hashlib.sha256()

    def update(self, data: bytes) -> None:
        self.parts.append(data)
        self.sink.update(data)


def test_fingerprints_of_files_without_collision_do_not_see_the_field():
    """The new field is left out of the digest while it is None, so every existing
    fingerprint and program key stays as it was."""
    plain, checked = _Recorder(), _Recorder()
    mech = linkopt.load(FOUR_BAR)
    digest(mech, plain)
    digest(linkopt.load(COLLIDING), checked)
    assert b"collision" not in plain.parts
    assert b"collision" in checked.parts
    bare = dataclasses.replace(mech, collision=None)
    assert linkopt._engine.model.fingerprint(bare) == linkopt._engine.model.fingerprint(
        mech
    )


# --- the exporters draw what is checked ---------------------------------------------


def test_mjcf_draws_the_checked_capsules_in_their_layers():
    import xml.etree.ElementTree as ET

    from linkopt._export.mjcf import mjcf_text

    mech = linkopt.load(LAYERED)
    root = ET.fromstring(mjcf_text(mech)[0])
    coupler = next(b for b in root.iter("body") if b.get("name") == "coupler")
    geoms = coupler.findall("geom")
    assert len(geoms) == int(np.sum(mech.collision.segment_bodies == 2))
    for geom in geoms:
        assert float(geom.get("size")) == pytest.approx(1.5e-3)
        fromto = np.array(geom.get("fromto").split(), dtype=float)
        assert fromto[2] == pytest.approx(8e-3) and fromto[5] == pytest.approx(8e-3)


# --- the command line ---------------------------------------------------------------


def test_verify_command_fails_and_names_the_pair(capsys):
    from linkopt._cli.main import main

    assert main(["verify", str(COLLIDING), "--resolution", "9"]) == 1
    out = capsys.readouterr().out
    assert "FAIL" in out and "collision: FAIL: ground and coupler" in out
    assert main(["verify", str(LAYERED), "--resolution", "9"]) == 0
    assert "collision: clear: ground and coupler 4.9 apart" in capsys.readouterr().out


def test_evaluate_command_reports_the_collision_term(capsys):
    from linkopt._cli.main import main

    assert main(["evaluate", str(COLLIDING)]) == 0
    out = capsys.readouterr().out
    assert "collision term" in out and "between ground and coupler" in out
    assert main(["evaluate", str(FOUR_BAR)]) == 0
    assert "collision" not in capsys.readouterr().out


# --- the collision term is differentiable in state and design -----------------------


def test_collision_term_gradients_match_finite_differences():
    """At a pose inside the band (not crossing), the term's gradient in the state and
    in a design parameter (the ground pivot D's x) matches central differences."""
    from linkopt._engine.collision import collision_value

    text = _with(
        COLLIDING,
        '[[parameters]]\nname = "d_x"\njoint = "D"\ncoordinate = "x"\n'
        "min = 55.0\nmax = 65.0\n",
    )
    mech = linkopt.loads(text, "design.toml")
    state = np.asarray(linkopt.solve_bk(mech, np.array([-0.08])).state)
    p0 = np.asarray(mech.design.p0)

    def value_of(s, p):
        return collision_value(mech, geometry(mech, p), s)

    # jitted (numpy arguments each time, so one trace each): op by op, the term, its
    # gradient and the differences compiled over two hundred small programs
    term = jax.jit(value_of)
    value = float(term(state, p0))
    assert 0.0 < value < 1.0  # in the band, short of contact
    grad_s, grad_p = jax.jit(jax.grad(value_of, argnums=(0, 1)))(state, p0)
    h = 1e-6
    fd_s = np.array(
        [
            (term(state + h * e, p0) - term(state - h * e, p0)) / (2 * h)
            for e in np.eye(len(state))
        ]
    )
    np.testing.assert_allclose(np.asarray(grad_s), fd_s, atol=1e-5)
    fd_p = (term(state, p0 + h) - term(state, p0 - h)) / (2 * h)
    assert float(grad_p[0]) == pytest.approx(float(fd_p), rel=1e-5, abs=1e-8)
    assert float(grad_p[0]) != 0.0


def test_meshes_put_each_body_in_its_layer():
    from linkopt._export.meshes import body_meshes

    mech = linkopt.load(LAYERED)
    coupler = body_meshes(mech)[2]
    assert coupler.is_watertight
    # capsules of radius 1.5 at z = 8, joint spheres 1.5 times that radius
    np.testing.assert_allclose(coupler.bounds[:, 2], [8 - 2.25, 8 + 2.25], atol=1e-9)
