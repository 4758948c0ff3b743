"""Points where the user put them (issue 44, part 2): ``[[points]].follow`` picks a
point's rule. ``"frame"`` (the default) keeps it fixed in its body's frame when a
design moves the body's pins; ``"anchors"`` keeps its affine place among them. A
design parameter on a pin of a two-joint stick moved the stick's tip 140 mm under the
old rule, the only one then; a point that a design moves far is now reported by
``check`` and ``evaluate`` and marked in the design figure."""

import json
import re

import numpy as np
import pytest
from conftest import MECHANISMS

import linkopt
from linkopt._cli.main import main
from linkopt._engine.geometry import geometry
from linkopt._engine.point_moves import MOVE_SHARE, box_designs, point_moves
from linkopt._errors import MechanismFileError
from linkopt._files.writer import write_design

FOUR_BAR = (MECHANISMS / "four_bar.toml").read_text()
B = np.array([0.0, 20.0, 0.0])
C = np.array([63.29705854077836, 49.891175622335055, 0.0])
#: The coupler's tip, on its line half a coupler beyond the pin C.
TIP = B + 1.5 * (C - B)
#: The initial design (ground_d, pin_x, pin_y) and one with the pin C moved 10 in x.
P0 = np.array([60.0, C[0], C[1]])
PIN_X = P0 + [0.0, 10.0, 0.0]


def coupler_tip(rule: str | None) -> str:
    """The four-bar with its coupler point at :data:`TIP` and the rule ``rule``
    (None: no ``follow`` key)."""
    old = 'position = [35.0, 55.0, 0.0]\nfollow = "anchors"\n'
    new = f"position = [{float(TIP[0])!r}, {float(TIP[1])!r}, 0.0]\n"
    if rule is not None:
        new += f'follow = "{rule}"\n'
    assert old in FOUR_BAR
    return FOUR_BAR.replace(old, new)


@pytest.fixture(scope="module")
def mechs():
    return {
        rule: linkopt.loads(coupler_tip(rule), f"{rule}.toml")
        for rule in ("frame", "anchors", None)
    }


def rest_tip(mech, design) -> np.ndarray:
    return np.asarray(geometry(mech, design).points)[0] * mech.length_scale


def test_a_point_fixed_in_its_frame_stays_where_the_user_put_it(mechs):
    for design in (P0, PIN_X, P0 + [5.0, -7.0, 9.0]):
        np.testing.assert_allclose(
            rest_tip(mechs["frame"], design), TIP, rtol=0, atol=1e-12
        )


def test_a_fixed_point_keeps_its_body_frame_coordinates_in_every_pose(mechs):
    """FK at a moved pin: the point in its body's frame (``Rᵀ (x_p - x_b)``) is its
    rest offset from the body origin, whatever the design."""
    mech = mechs["frame"]
    coupler = mech.body_names.index("coupler")
    local = TIP - mech.body_origins[coupler]
    for design in (P0, PIN_X):
        state = np.asarray(linkopt.solve_fk(mech, np.array([0.3]), design=design).state)
        body = state.reshape(-1, 7)[coupler]
        origin, (w, x, y, z) = body[:3] * mech.length_scale, body[3:]
        rot = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
        tip = np.asarray(linkopt.point_positions(mech, state, design=design))[0]
        np.testing.assert_allclose(rot.T @ (tip - origin), local, atol=1e-9)


def test_a_point_following_the_anchors_keeps_its_affine_place(mechs):
    mech = mechs["anchors"]
    for design in (PIN_X, P0 + [0.0, -8.0, 6.0]):
        moved = C + [design[1] - C[0], design[2] - C[1], 0.0]
        np.testing.assert_allclose(
            rest_tip(mech, design), B + 1.5 * (moved - B), rtol=0, atol=1e-12
        )


def test_the_default_rule_is_fixed_in_the_frame(mechs):
    np.testing.assert_array_equal(
        rest_tip(mechs[None], PIN_X), rest_tip(mechs["frame"], PIN_X)
    )


@pytest.mark.parametrize(
    "edit, words",
    [
        ('follow = "frame"', "points[0].follow: expected one of 'frame', 'anchors'"),
        ("follow = 3", "points[0].follow: expected a non-empty string"),
    ],
)
def test_a_bad_rule_is_one_line_naming_the_field(edit, words):
    text = coupler_tip(None).replace(
        "[[points]]\n", "[[points]]\n" + edit.replace("frame", "fram") + "\n"
    )
    with pytest.raises(MechanismFileError, match=re.escape(words)):
        linkopt.loads(text, "bad.toml")


def test_a_point_given_by_joint_takes_no_rule():
    text = (MECHANISMS / "five_bar.toml").read_text()
    text = text.replace('joint = "tip"\n', 'joint = "tip"\nfollow = "frame"\n', 1)
    with pytest.raises(MechanismFileError, match="follows that joint"):
        linkopt.loads(text, "bad.toml")


@pytest.mark.parametrize("rule", ["frame", "anchors", None])
def test_the_writer_writes_the_rule_back(mechs, rule, tmp_path):
    mech = mechs[rule]
    path = write_design(mech, PIN_X, 10.0, tmp_path / "written.toml")
    written = linkopt.load(path)
    assert written.raw["points"][0]["follow"] == (rule or "frame")
    np.testing.assert_allclose(written.point_positions[0], rest_tip(mech, PIN_X))
    # reloaded, the point keeps its rule: the same move from the written design
    step = np.array([0.0, -4.0, 3.0])
    np.testing.assert_allclose(
        rest_tip(written, PIN_X + step) - rest_tip(written, PIN_X),
        rest_tip(mech, PIN_X + step) - rest_tip(mech, PIN_X),
        atol=1e-9,
    )


def test_a_point_that_follows_the_anchors_far_is_reported(mechs):
    """Moving C 10 in x moves the tip 15 and the centroid of the coupler's pins 5:
    10 relative to them, 13 % of the coupler's span |C - B|."""
    (move,) = point_moves(mechs["anchors"], PIN_X[None])
    assert (move.point, move.body) == ("coupler_point", "coupler")
    assert move.size == pytest.approx(np.linalg.norm(C - B), rel=1e-12)
    assert move.distance == pytest.approx(10.0, rel=1e-12)
    assert move.share > MOVE_SHARE
    np.testing.assert_allclose(move.moved - move.rest, [15.0, 0.0, 0.0], atol=1e-12)
    assert point_moves(mechs["frame"], box_designs(mechs["frame"])) == ()
    small = P0 + [0.0, 5.0, 0.0]  # 5 relative to the pins: 6.5 % of the span
    assert point_moves(mechs["anchors"], small[None]) == ()


def test_check_reports_the_moved_point(tmp_path, capsys):
    path = tmp_path / "tip.toml"
    path.write_text(coupler_tip("anchors"))
    assert main(["check", str(path)]) == 0
    out = capsys.readouterr().out
    assert "1 point(s) moved by more than 10 % of their body's anchor span" in out
    assert "point 'coupler_point' on 'coupler'" in out
    assert main(["check", str(path), "--json"]) == 0
    (move,) = json.loads(capsys.readouterr().out)["moved_points"]
    # the box's worst corner for the pin C: its relative move is C's own (1.5 - 0.5)
    corners = [np.array([x, y, 0.0]) for x in (50.0, 75.0) for y in (35.0, 65.0)]
    worst = max(corners, key=lambda c: np.linalg.norm(c - C))
    assert move["distance"] == pytest.approx(np.linalg.norm(worst - C), rel=1e-9)
    assert (move["design"]["pin_x"], move["design"]["pin_y"]) == tuple(worst[:2])
    path.write_text(coupler_tip("frame"))
    assert main(["check", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["moved_points"] == []


def test_evaluate_reports_the_moved_point(tmp_path, capsys):
    path = tmp_path / "tip.toml"
    path.write_text(coupler_tip("anchors"))
    design = ",".join(str(v) for v in PIN_X)
    assert main(["evaluate", str(path), "--design", design, "--json"]) == 0
    (move,) = json.loads(capsys.readouterr().out)["moved_points"]
    assert move["point"] == "coupler_point"
    assert move["distance"] == pytest.approx(10.0, rel=1e-9)
    assert move["moved"] == pytest.approx(list(TIP + [15.0, 0.0, 0.0]), abs=1e-9)
    assert main(["evaluate", str(path), "--design", design]) == 0
    assert "point 'coupler_point' on 'coupler' moves 10 mm" in capsys.readouterr().out


def test_the_design_figure_marks_the_moved_point(mechs):
    from linkopt._draw import figures
    from linkopt._draw.plots import mark_moves

    fig, ax = figures.subplots()
    assert mark_moves(ax, mechs["anchors"], PIN_X, "tab:blue", (0, 1)) == 1
    (line,) = [a for a in ax.lines if a.get_gid() == "moved-point"]
    np.testing.assert_allclose(line.get_xydata(), [TIP[:2], TIP[:2] + [15.0, 0.0]])
    assert mark_moves(ax, mechs["frame"], PIN_X, "tab:blue", (0, 1)) == 0
    assert mark_moves(ax, mechs["anchors"], None, "tab:blue", (0, 1)) == 0
