"""``linkopt animate`` and :func:`linkopt.animate`: a GIF of exactly one image per
frame, whose drawn end-effector positions are the FK/BK solutions of the path (checked
against the five-bar's closed form), on mechanisms with 1, 2 and 3 motors and on a
four-bar written inline; an unreached row exits 1 naming it, bad arguments exit 2."""

import matplotlib
import numpy as np
import pytest
from conftest import MECHANISMS
from five_bar_closed_form import forward, inverse
from PIL import Image

import linkopt
from linkopt._cli.main import main
from linkopt._design.motion import (
    MAX_FRAMES,
    PULL_IN,
    default_path,
    resample_loop,
    tour,
    traced_points,
)
from linkopt._draw.animation import plane_basis, quantised, write_run_motions

FRAMES = 8

#: A crank-rocker four-bar as a user writes it from the README's file format.
FOUR_BAR = """
[mechanism]
name = "four-bar"
ground = "ground"
units = "mm"

[[bodies]]
name = "ground"
[[bodies]]
name = "crank"
[[bodies]]
name = "coupler"
[[bodies]]
name = "rocker"

[[joints]]
name = "A"
type = "revolute"
bodies = ["ground", "crank"]
anchor = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]

[[joints]]
name = "B"
type = "revolute"
bodies = ["crank", "coupler"]
anchor = [0.0, 20.0, 0.0]
axis = [0.0, 0.0, 1.0]

[[joints]]
name = "C"
type = "revolute"
bodies = ["coupler", "rocker"]
anchor = [40.0, 30.0, 0.0]
axis = [0.0, 0.0, 1.0]

[[joints]]
name = "D"
type = "revolute"
bodies = ["rocker", "ground"]
anchor = [40.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]

[[motors]]
name = "crank"
joint = "A"

[[points]]
name = "tip"
body = "coupler"
position = [20.0, 40.0, 0.0]

[[outputs]]
name = "x"
point = "tip"
coordinate = "x"
min = 14.0
max = 22.0

[[parameters]]
name = "coupler_x"
joint = "C"
coordinate = "x"
min = 30.0
max = 50.0
"""


def gif_frames(path) -> int:
    with Image.open(path) as image:
        return image.n_frames


def write_csv(path, header: str, rows) -> str:
    lines = [header] + [",".join(repr(float(v)) for v in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return str(path)


def circle(centre, radius, count=FRAMES):
    angle = np.linspace(0.0, 2 * np.pi, count, endpoint=False)
    return np.asarray(centre) + radius * np.stack([np.cos(angle), np.sin(angle)], 1)


def test_motor_rows_draw_the_closed_form_tip(tmp_path, five_bar):
    motors = circle([0.1, -0.1], 0.25)
    out = tmp_path / "motion.gif"
    item = linkopt.animate(five_bar, out, motors=motors)
    assert gif_frames(out) == FRAMES and item.kind == "fk" and item.reached.all()
    assert item.trace_names == ("ee",)
    np.testing.assert_allclose(item.trace[:, 0, :2], forward(motors), atol=1e-9)
    np.testing.assert_allclose(item.motors, motors, atol=1e-9)
    path = linkopt.solve_fk_path(five_bar, motors)
    np.testing.assert_allclose(
        item.trace[:, 0], linkopt.point_positions(five_bar, path.state)[:, 0], atol=1e-9
    )


def _figure_frames(count: int) -> list:
    """RGB frames of a figure like an animation's: a colour bar, and lines coloured
    from it that move from frame to frame (anti-aliased edges, thin strokes)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    frames = []
    for k in range(count):
        fig = Figure(figsize=(4, 3), dpi=72)
        FigureCanvasAgg(fig)
        ax = fig.add_subplot()
        image = ax.imshow(np.linspace(0, 1, 64)[None], cmap="viridis", aspect="auto")
        fig.colorbar(image, ax=ax)
        for j in range(6):
            colour = matplotlib.colormaps["viridis"]((j + k) / 9)
            ax.plot([0, 63], [-0.4 + 0.1 * j, 0.4 - 0.1 * k], color=colour, lw=1 + j)
        fig.canvas.draw()
        frames.append(Image.fromarray(np.asarray(fig.canvas.buffer_rgba())[..., :3]))
    return frames


def test_gif_frames_keep_the_rendered_colours():
    """The palette frames written are the rendered frames to within a few colour
    levels: a palette that lost the colour bar's or the lines' colours fails (32
    colours give a 99.9th percentile error of about 30 levels here)."""
    frames = _figure_frames(4)
    errors = np.stack(
        [
            np.abs(np.asarray(q.convert("RGB"), int) - np.asarray(f, int))
            for q, f in zip(quantised(frames), frames)
        ]
    )
    assert errors.mean() < 2.0 and np.percentile(errors, 99.9) <= 16, (
        errors.mean(),
        np.percentile(errors, 99.9),
    )


def test_output_rows_reach_the_rows_with_the_closed_form_motors(tmp_path, five_bar):
    outputs = circle([0.0, 55.0], 12.0)
    item = linkopt.animate(five_bar, tmp_path / "motion.gif", outputs=outputs)
    assert gif_frames(tmp_path / "motion.gif") == FRAMES and item.kind == "bk"
    np.testing.assert_allclose(item.trace[:, 0, :2], outputs, atol=1e-9)
    np.testing.assert_allclose(item.motors, inverse(outputs), atol=1e-9)
    f = linkopt.f_sing(five_bar, item.states)
    np.testing.assert_allclose(item.f_sing, f, rtol=1e-12)


@pytest.mark.parametrize("kind", ["motors", "outputs"])
def test_cli_path_csv_of_motor_or_output_rows(tmp_path, capsys, kind):
    rows = circle([0.1, 0.0], 0.2) if kind == "motors" else circle([0.0, 55.0], 10.0)
    header = "left,right" if kind == "motors" else "x,y"
    csv = write_csv(tmp_path / "path.csv", header, rows)
    out = tmp_path / "m.gif"
    file = str(MECHANISMS / "five_bar.toml")
    assert main(["animate", file, "--out", str(out), "--path", csv]) == 0
    assert gif_frames(out) == FRAMES
    assert f"{kind[:-1]} rows" in capsys.readouterr().out


def test_cli_unreachable_row_exits_1_and_names_it(tmp_path, capsys):
    rows = circle([0.0, 55.0], 10.0, 5)
    rows[2] = [0.0, 200.0]  # beyond crank + distal link
    csv = write_csv(tmp_path / "far.csv", "x,y", rows)
    out = tmp_path / "m.gif"
    file = str(MECHANISMS / "five_bar.toml")
    assert main(["animate", file, "--out", str(out), "--path", csv]) == 1
    err = capsys.readouterr().err.strip()
    assert "row 3 (x=0, y=200)" in err and len(err.splitlines()) == 1
    assert not out.exists()


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--frames", "0"], "--frames: expected at least 1"),
        (["--frames", str(MAX_FRAMES + 1)], f"expected at most {MAX_FRAMES} frames"),
        (["--frames", "many"], "invalid int value"),
        (["--frames", "4", "--path", "p.csv"], "--frames: not with --path"),
    ],
)
def test_cli_bad_frames_exit_2_with_one_line(tmp_path, capsys, extra, message):
    (tmp_path / "p.csv").write_text("x,y\n0,50\n")
    extra = [str(tmp_path / e) if e == "p.csv" else e for e in extra]
    out = str(tmp_path / "m.gif")
    assert (
        main(["animate", str(MECHANISMS / "five_bar.toml"), "--out", out] + extra) == 2
    )
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_cli_csv_header_must_name_motors_or_outputs(tmp_path, capsys):
    csv = write_csv(tmp_path / "p.csv", "a,b", [[0.0, 50.0]])
    out = str(tmp_path / "m.gif")
    assert (
        main(
            ["animate", str(MECHANISMS / "five_bar.toml"), "--out", out, "--path", csv]
        )
        == 2
    )
    assert "must name the motors (left,right) or the outputs (x,y)" in (
        capsys.readouterr().err
    )


def test_one_motor_default_loop_runs_through_its_targets(tmp_path):
    mech = linkopt.load(MECHANISMS / "jansen_1dof.toml")
    out = tmp_path / "jansen.gif"
    assert (
        main(
            [
                "animate",
                str(MECHANISMS / "jansen_1dof.toml"),
                "--out",
                str(out),
                "--frames",
                str(FRAMES),
            ]
        )
        == 0
    )
    assert gif_frames(out) == FRAMES
    item = linkopt.motion(mech, frames=FRAMES)
    # the loop goes from the target nearest the rest pose to both ends and back
    np.testing.assert_allclose(item.outputs, item.path, atol=1e-9)
    assert np.isclose(item.path.min(), mech.output_min[0])
    assert np.isclose(item.path.max(), mech.output_max[0])


def test_default_loop_out_of_reach_is_pulled_in_towards_the_rest_outputs(
    five_bar, tmp_path, capsys
):
    """The initial five-bar cannot reach its box's upper corners: those frames move
    onto the line from the rest outputs to them, short of the branch's limit, and the
    command says so."""
    file, out = str(MECHANISMS / "five_bar.toml"), tmp_path / "m.gif"
    assert main(["animate", file, "--out", str(out), "--frames", str(FRAMES)]) == 0
    assert gif_frames(out) == FRAMES
    assert "of 8 frames of the default loop are out of" in capsys.readouterr().out
    loop = default_path(five_bar, FRAMES)
    item = linkopt.motion(five_bar, frames=FRAMES)
    assert item.default and item.reached.all()
    np.testing.assert_allclose(item.outputs, item.path, atol=1e-9)
    rest = np.asarray(linkopt.output_values(five_bar, linkopt.rest_state(five_bar)))
    moved = np.linalg.norm(item.path - loop, axis=1) > 1e-9
    assert 0 < moved.sum() < FRAMES
    wanted, got = loop[moved] - rest, item.path[moved] - rest
    fraction = np.sum(got * wanted, axis=1) / np.sum(wanted**2, axis=1)
    np.testing.assert_allclose(got, fraction[:, None] * wanted, atol=1e-9)
    assert np.all((fraction > 0) & (fraction < PULL_IN))
    unpulled = linkopt.solve_bk(five_bar, loop[moved])
    assert not np.any(unpulled.converged)


@pytest.mark.slow
def test_three_motor_neck_output_loop(tmp_path):
    mech = linkopt.load(MECHANISMS / "neck_3dof.toml")
    angle = np.linspace(0, 2 * np.pi, FRAMES, endpoint=False)
    outputs = 0.15 * np.stack([np.cos(angle), np.sin(angle), np.sin(2 * angle)], 1)
    item = linkopt.animate(mech, tmp_path / "neck.gif", outputs=outputs)
    assert gif_frames(tmp_path / "neck.gif") == FRAMES and item.reached.all()
    assert plane_basis(mech) is None  # spatial: drawn in 3-D
    np.testing.assert_allclose(item.outputs, outputs, atol=1e-9)
    ahead = linkopt.solve_fk_path(mech, item.motors)
    np.testing.assert_allclose(ahead.state, item.states, atol=1e-9)


def test_inline_four_bar_default_loop_and_run_motions(tmp_path):
    mech = linkopt.loads(FOUR_BAR)
    basis = plane_basis(mech)
    np.testing.assert_array_equal(basis, np.eye(3)[:2])
    item = linkopt.animate(mech, tmp_path / "four.gif", frames=FRAMES)
    assert gif_frames(tmp_path / "four.gif") == FRAMES
    np.testing.assert_allclose(item.trace[:, 0, 0], item.path[:, 0], atol=1e-9)
    one = linkopt.animate(mech, tmp_path / "one.gif", frames=1, design=[35.0])
    assert gif_frames(tmp_path / "one.gif") == 1 and one.reached.all()
    names = write_run_motions(mech, mech, tmp_path, np.array([42.0]), frames=FRAMES)
    assert names == ["motion_initial.gif", "motion_optimized.gif"]
    assert [gif_frames(tmp_path / n) for n in names] == [FRAMES, FRAMES]


def test_tour_of_the_three_by_three_grid_is_shortest():
    grid = np.array([[i, j] for i in (0.0, 0.5, 1.0) for j in (0.0, 0.5, 1.0)])
    order = tour(grid, first=2)
    assert sorted(order) == list(range(9)) and order[0] == 2
    ring = grid[order + order[:1]]
    # no Hamiltonian cycle of unit steps exists on 9 cells: 8 steps and one diagonal
    length = np.sum(np.linalg.norm(np.diff(ring, axis=0), axis=1))
    assert length == pytest.approx(8 * 0.5 + 0.5 * np.sqrt(2))


def test_resampled_loop_has_equal_steps_and_does_not_repeat_its_start():
    square = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
    frames = resample_loop(square, 8, np.array([2.0, 2.0]))
    ring = np.vstack([frames, frames[:1]])
    steps = np.linalg.norm(np.diff(ring, axis=0), axis=1)
    np.testing.assert_allclose(steps, 1.0)
    np.testing.assert_allclose(frames[0], [0.0, 0.0])


def test_reported_position_outputs_are_traced():
    """The four-bar's output is the rocker angle; its coupler point's x and y are
    reported outputs, so the animation traces that point (and only it)."""
    mech = linkopt.load(MECHANISMS / "four_bar.toml")
    assert set(mech.output_kinds) == {"angle"}
    traced = [mech.point_names[i] for i in traced_points(mech)]
    assert traced == ["coupler_point"]


def test_a_run_animates_along_its_targets_with_the_file_mechanism(five_bar):
    """``loop_of``: the loop through the run's targets (the file's and an added one),
    solved with the file's mechanism; the frames are those the run's mechanism gives."""
    from linkopt._design.rounds import with_targets

    design = five_bar.design.p0.copy()
    current = with_targets(five_bar, [[0.0, 30.0]])
    item = linkopt.motion(five_bar, design=design, frames=FRAMES, loop_of=current)
    same = linkopt.motion(current, design=design, frames=FRAMES)
    assert item.default
    assert not np.allclose(
        default_path(five_bar, FRAMES), default_path(current, FRAMES)
    )
    np.testing.assert_array_equal(item.path, same.path)
    np.testing.assert_allclose(item.outputs, same.outputs, atol=1e-9)
    np.testing.assert_allclose(item.f_sing, same.f_sing, rtol=1e-9)
    with pytest.raises(linkopt.InputError, match="loop_of"):
        linkopt.motion(five_bar, frames=FRAMES, loop_of=linkopt.loads(FOUR_BAR))


#: A planar 3R arm whose outputs are its tip's x and y and the last link's heading, as
#: a planar parallel platform's are: two positions and an angle.
PLANAR_3R = """
[mechanism]
name = "planar 3R"
ground = "ground"
[[bodies]]
name = "ground"
[[bodies]]
name = "a"
[[bodies]]
name = "b"
[[bodies]]
name = "c"
[[joints]]
name = "j1"
type = "revolute"
bodies = ["ground", "a"]
anchor = [0.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "j2"
type = "revolute"
bodies = ["a", "b"]
anchor = [30.0, 0.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[joints]]
name = "j3"
type = "revolute"
bodies = ["b", "c"]
anchor = [30.0, 25.0, 0.0]
axis = [0.0, 0.0, 1.0]
[[motors]]
name = "m1"
joint = "j1"
[[motors]]
name = "m2"
joint = "j2"
[[motors]]
name = "m3"
joint = "j3"
[[points]]
name = "tip"
body = "c"
position = [45.0, 25.0, 0.0]
[[outputs]]
name = "heading"
kind = "orientation"
body = "c"
angle = "yaw"
min = -0.2
max = 0.2
[[outputs]]
name = "y"
point = "tip"
coordinate = "y"
min = 20.0
max = 30.0
[[outputs]]
name = "x"
point = "tip"
coordinate = "x"
min = 40.0
max = 50.0
"""


@pytest.mark.parametrize("text", ["five_bar", PLANAR_3R])
def test_target_rectangle_is_drawn_for_two_positions_beside_an_angle(text):
    """Regression: the rectangle was drawn only when the outputs were exactly two
    positions; a planar platform's x, y and heading got none."""
    import matplotlib.pyplot as plt

    from linkopt._draw.animation import target_box

    mech = linkopt.load(MECHANISMS / "five_bar.toml") if text == "five_bar" else None
    mech = mech or linkopt.loads(text)
    basis = plane_basis(mech)
    fig, ax = plt.subplots()
    target_box(ax, mech, basis)
    (line,) = [ln for ln in ax.lines if ln.get_label() == "target range"]
    x, y = (mech.output_names.index(n) for n in ("x", "y"))
    lo, hi = mech.output_min, mech.output_max
    assert sorted(set(line.get_xdata())) == [lo[x], hi[x]]
    assert sorted(set(line.get_ydata())) == [lo[y], hi[y]]
    plt.close(fig)


def test_a_plate_is_drawn_as_its_hull_without_its_interior_point():
    """Regression: a platform with three joints and a centre point was drawn as a
    four-sided ring through the centre; a bar's collinear members are one segment."""
    from linkopt._draw.animation import body_outline

    corners = np.array([[1.0, 0.0, 0.0], [-0.5, 0.8, 0.0], [-0.5, -0.8, 0.0]])
    coords = np.vstack([corners[:2], [0.0, 0.0, 0.0], corners[2:]])  # centre third
    ring = body_outline(np.arange(4) + 10, coords)
    assert ring[0] == ring[-1] and sorted(ring[:-1]) == [10, 11, 13]
    bar = np.array([[0.0, 0.0, 0.0], [2.0, 1.0, 0.0], [1.0, 0.5, 0.0]])
    assert sorted(body_outline(np.arange(3), bar)) == [0, 1]
