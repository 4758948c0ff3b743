"""Welded parts change nothing: bodies joined by ``fixed`` joints are one rigid body
for every metric (:mod:`linkopt._engine.welding`). An inert part welded onto a moving
body once changed f_sing at one pose from 52.48 to 71.48 and α₋ from 38.5 to 42.8;
here shipped mechanisms that between them hold every joint type and motor kind get
such a part, and every number is compared with the file's own to 1e-10."""

import copy

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._design.conditioning import alpha_minus, rest_conditioning
from linkopt._engine.geometry import rest_state
from linkopt._engine.welding import part_state, parts
from linkopt._files.writer import dumps

#: Every joint type and motor kind of the shipped files (mechanisms/), each welded
#: structure compiling its own programs (about half a minute each, cold): revolute
#: loops (five-bar, four-bar, the spherical five-bar's inclined axes), prismatic joints
#: with linear motors in an assembled drawing (backhoe), spherical and universal joints
#: (finger), rods between two ball joints with idle spins (delta). The Stewart
#: platform, the necks and the Jansen legs repeat these.
WELDED_ON = ("backhoe", "delta", "finger", "five_bar", "four_bar", "spherical_five_bar")
#: The five-bar and four-bar are also evaluated (f_design); the others compile
#: their evaluation for minutes, their σ_min, f_sing, α₋ and FK are compared.
EVALUATED = ("five_bar", "four_bar")


def moving_body(mech) -> int:
    """The body a motor turns (the second body of the first motor's joint)."""
    return int(mech.joint_bodies[mech.motor_joints[0], 1])


def pin(mech, body: int) -> int:
    """The body's first joint whose anchor is fixed in it: not a prismatic or
    cylindrical joint, whose anchor slides on one of its two bodies (a cylinder's rod
    carries its slide's anchor only at rest)."""
    sliding = ("prismatic", "cylindrical")
    return next(j for j in mech.joints_on(body) if mech.joint_types[j] not in sliding)


def with_welded_part(mech, onto: int | None = None) -> str:
    """The file of ``mech`` (its assembled tables) with a part welded by a ``fixed``
    joint onto a moving body, at that body's first anchor (the anchors' span, hence
    the reference length, is unchanged), with a named point at the body's anchor
    centroid."""
    data = copy.deepcopy(mech.raw)
    body = moving_body(mech) if onto is None else onto
    joints = mech.joints_on(body)
    data["bodies"].append({"name": "welded_part"})
    data["joints"].append(
        {
            "name": "weld",
            "type": "fixed",
            "bodies": [mech.body_names[body], "welded_part"],
            "anchor": [float(v) for v in mech.anchors[pin(mech, body)]],
        }
    )
    centre = mech.anchors[joints].mean(axis=0)
    data.setdefault("points", []).append(
        {"name": "on_part", "body": "welded_part", "position": list(map(float, centre))}
    )
    data["mechanism"].pop("assemble", None)  # the tables are assembled already
    return dumps(data)


def motor_rows(mech) -> np.ndarray:
    """The rest pose and two small motor moves (0.05 rad, or 1 % of the reference
    length for linear motors)."""
    step = np.where(mech.motor_linear, 0.01 * mech.length_scale, 0.05)
    signs = np.array([np.ones(mech.num_motors), (-1.0) ** np.arange(mech.num_motors)])
    return np.vstack([np.zeros(mech.num_motors), signs * step])


@pytest.fixture(scope="module", params=WELDED_ON)
def pair(request):
    mech = linkopt.load(MECHANISMS / f"{request.param}.toml")
    welded = linkopt.loads(with_welded_part(mech), f"{request.param}_welded.toml")
    return request.param, mech, welded


def test_the_part_is_merged_into_its_body(pair):
    _, mech, welded = pair
    assert welded.body_names == mech.body_names
    assert welded.state_size == mech.state_size
    assert parts(welded).body_names == mech.body_names + ("welded_part",)
    assert welded.joint_types[-1] == "welded"


def test_fk_sigma_min_and_f_sing_are_unchanged(pair):
    _, mech, welded = pair
    rows = motor_rows(mech)
    one, two = linkopt.solve_fk(mech, rows), linkopt.solve_fk(welded, rows)
    assert np.asarray(one.converged).tolist() == np.asarray(two.converged).tolist()
    np.testing.assert_allclose(two.state, one.state, rtol=0, atol=1e-10)
    np.testing.assert_allclose(
        linkopt.output_values(welded, two.state) / mech.output_scale,
        linkopt.output_values(mech, one.state) / mech.output_scale,
        rtol=0,
        atol=1e-10,
    )
    # the file's rest state exactly (motor row 0 is the rest pose) and the two moves,
    # in the batch shape of this file's other σ_min checks: one program per shape
    states = np.asarray(one.state).copy()
    states[0] = rest_state(mech)
    np.testing.assert_allclose(
        linkopt.singular_values(welded, states),
        linkopt.singular_values(mech, states),
        rtol=1e-10,
    )
    np.testing.assert_allclose(
        linkopt.f_sing(welded, states), linkopt.f_sing(mech, states), rtol=1e-10
    )


def test_rest_conditioning_and_alpha_minus_are_unchanged(pair):
    _, mech, welded = pair
    one, two = rest_conditioning(mech), rest_conditioning(welded)
    assert two.f_sing == pytest.approx(one.f_sing, rel=1e-10)
    np.testing.assert_allclose(two.jacobian_sigmas, one.jacobian_sigmas, rtol=1e-10)
    if not one.near_singular:
        assert alpha_minus(welded) == pytest.approx(alpha_minus(mech), rel=1e-10)


def test_the_point_on_the_part_reads_as_the_same_point_on_its_body(pair):
    """FK of the point on the welded part equals FK of the same point placed on the
    body it is welded to (with the same rule), at every pose."""
    name, mech, welded = pair
    data = linkopt.loads(with_welded_part(mech), "x.toml").raw
    data = copy.deepcopy(data)
    data["points"][-1]["body"] = mech.body_names[moving_body(mech)]
    data["bodies"] = data["bodies"][:-1]
    data["joints"] = data["joints"][:-1]
    on_body = linkopt.loads(dumps(data), f"{name}_on_body.toml")
    rows = motor_rows(mech)
    state = np.asarray(linkopt.solve_fk(welded, rows).state)
    np.testing.assert_allclose(
        np.asarray(linkopt.point_positions(welded, state))[:, -1],
        np.asarray(linkopt.point_positions(on_body, state))[:, -1],
        rtol=0,
        atol=1e-9,
    )


def test_a_state_gives_each_part_its_pose(pair):
    """:func:`part_state`: the part rides on its body: its fixed joint's residual on
    the parts' mechanism is zero, and its pose is its body's."""
    _, mech, welded = pair
    state = np.asarray(linkopt.solve_fk(welded, motor_rows(mech)).state)
    whole = part_state(welded, state)
    assert whole.shape == (len(state), parts(welded).state_size)
    np.testing.assert_allclose(whole[:, : mech.state_size], state, atol=1e-15)
    joints = np.asarray(linkopt.joint_positions(parts(welded), whole))
    body = moving_body(mech)
    first = pin(mech, body)
    np.testing.assert_allclose(joints[:, -1], joints[:, first], atol=1e-9)
    part = whole.reshape(len(state), -1, 7)[:, -1]
    np.testing.assert_allclose(
        part[:, 3:], state.reshape(len(state), -1, 7)[:, body, 3:], atol=1e-15
    )


@pytest.mark.parametrize("name", EVALUATED)
def test_f_design_is_unchanged(name):
    mech = linkopt.load(MECHANISMS / f"{name}.toml")
    welded = linkopt.loads(with_welded_part(mech), f"{name}_welded.toml")
    one, two = linkopt.evaluate(mech), linkopt.evaluate(welded)
    assert float(two.f_design) == pytest.approx(float(one.f_design), rel=1e-10)
    np.testing.assert_allclose(two.ik_f_sing, one.ik_f_sing, rtol=1e-10)
    np.testing.assert_allclose(two.adv_f_sing, one.adv_f_sing, rtol=1e-10)


def test_a_chain_of_welds_merges_into_the_ground_or_first_body():
    """Two parts welded in a chain onto the five-bar's proximal link, and one welded
    to the ground: the chain's root is the link, the ground roots its own group."""
    mech = linkopt.load(MECHANISMS / "five_bar.toml")
    data = copy.deepcopy(mech.raw)
    link = mech.body_names[moving_body(mech)]
    anchor = [float(v) for v in mech.anchors[pin(mech, moving_body(mech))]]
    for name, onto in (("a", link), ("b", "a"), ("c", mech.body_names[mech.ground])):
        data["bodies"].append({"name": name})
        data["joints"].append(
            {"name": f"w{name}", "type": "fixed", "bodies": [name, onto],
             "anchor": anchor}
        )  # fmt: skip
    welded = linkopt.loads(dumps(data), "chain.toml")
    assert welded.body_names == mech.body_names
    assert welded.ground == mech.ground
    states = np.asarray(linkopt.solve_fk(mech, motor_rows(mech)).state)
    np.testing.assert_allclose(
        linkopt.singular_values(welded, states),
        linkopt.singular_values(mech, states),
        rtol=1e-10,
    )


def test_exports_and_the_figure_show_the_parts(tmp_path):
    """The MJCF and the meshes keep the part as its own body, rigid on the body it is
    welded to (a child body without a joint); the MJCF
    joint values of a merged state are those of the file without the part; the
    design figure draws it."""
    from linkopt._draw.plots import plot_mechanism
    from linkopt._export.meshes import body_meshes
    from linkopt._export.mjcf import joint_values, mjcf_text

    mech = linkopt.load(MECHANISMS / "five_bar.toml")
    welded = linkopt.loads(with_welded_part(mech), "five_bar_welded.toml")
    text, _ = mjcf_text(welded)
    import xml.etree.ElementTree as ET

    (part,) = [
        b for b in ET.fromstring(text).iter("body") if b.get("name") == "welded_part"
    ]
    assert part.find("joint") is None  # rigid on its body: a tree edge with no joint
    assert len(body_meshes(welded)) == mech.num_bodies + 1
    state = np.asarray(linkopt.solve_fk(welded, motor_rows(mech)).state)
    one, two = joint_values(mech, state), joint_values(welded, state)
    for name, value in one.items():
        np.testing.assert_allclose(two[name], value, atol=1e-9)
    assert plot_mechanism(welded, tmp_path / "welded.png").stat().st_size > 0


def test_a_welded_parts_capsules_keep_their_layer_and_pairs_merge():
    """A part welded onto the collision four-bar's coupler, in its own layer: its
    capsule rides on the coupler with the part's layer offset (capsule ends of the
    merged state equal those of the parts' state), no pair lies inside the group and
    each merged pair is checked once."""
    from linkopt._engine.collision import capsule_ends
    from linkopt._engine.geometry import geometry

    mech = linkopt.load(MECHANISMS / "four_bar_collision.toml")
    coupler = mech.body_names.index("coupler")
    data = linkopt.loads(with_welded_part(mech, onto=coupler), "x.toml").raw
    data = copy.deepcopy(data)
    data["bodies"][-1]["layer"] = 3.0
    welded = linkopt.loads(dumps(data), "four_bar_collision_welded.toml")
    model, whole = welded.collision, parts(welded)
    part = whole.body_names.index("welded_part")
    assert part in whole.collision.segment_bodies
    assert np.all(model.pairs[:, 0] < model.pairs[:, 1])
    assert len({tuple(p) for p in model.pairs}) == len(model.pairs)
    owners = model.pairs[model.capsule_owners]
    np.testing.assert_array_equal(
        np.sort(model.segment_bodies[model.capsule_pairs], axis=1), owners
    )
    states = np.asarray(linkopt.solve_fk(welded, motor_rows(mech)).state)
    for state, full in zip(states, part_state(welded, states)):
        np.testing.assert_allclose(
            capsule_ends(welded, geometry(welded), state),
            capsule_ends(whole, geometry(whole), full),
            rtol=0,
            atol=1e-12,
        )


def test_check_names_the_welded_parts(tmp_path, capsys):
    from linkopt._cli.main import main

    mech = linkopt.load(MECHANISMS / "five_bar.toml")
    path = tmp_path / "welded.toml"
    path.write_text(with_welded_part(mech))
    assert main(["check", str(path)]) == 0
    body = mech.body_names[moving_body(mech)]
    assert f"1 welded part(s), one body with the part they are welded to: " \
        f"welded_part on {body}" in capsys.readouterr().out  # fmt: skip
    assert main(["check", str(path), "--json"]) == 0
    import json

    info = json.loads(capsys.readouterr().out)
    assert info["welded"] == {"welded_part": body}
    assert info["bodies"] == list(mech.body_names)


def test_a_written_design_keeps_the_parts(tmp_path):
    """``optimized.toml`` of a welded file: every body keeps its own origin and the
    file reads back to the same merged mechanism."""
    from linkopt._files.writer import write_design

    mech = linkopt.load(MECHANISMS / "five_bar.toml")
    welded = linkopt.loads(with_welded_part(mech), "five_bar_welded.toml")
    path = write_design(welded, welded.design.p0, 10.0, tmp_path / "w.toml")
    again = linkopt.load(path)
    assert parts(again).body_names == parts(welded).body_names
    np.testing.assert_allclose(
        parts(again).body_origins, parts(welded).body_origins, atol=1e-12
    )
    np.testing.assert_allclose(again.body_origins, mech.body_origins, atol=1e-12)
