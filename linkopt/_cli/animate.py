"""``linkopt animate FILE --out motion.gif [--design …] [--frames N] [--path CSV]``:
a GIF of the mechanism moving along a path (:mod:`linkopt._draw.animation`, frames by
:mod:`linkopt._design.motion`).

``--path`` is a CSV file whose header names the motors (the rows are solved by forward
kinematics) or the outputs (backward kinematics), one row per frame; without it the
mechanism runs the default loop through its target range in ``--frames`` frames. A
frame that is not reached on the rest pose's assembly branch exits with 1 and names the
row (its data row, 1-based, as ``linkopt fk``/``bk`` count them); the default loop is
drawn also where it is out of reach, with a note. Bad arguments exit with 2.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np

from .._design.settings import DEFAULT_FRAMES, MAX_FRAMES
from .._errors import InputError
from .values import MAX_ROWS, design_arg, load, read_values


def _header(arg: str) -> list[str] | None:
    """The stripped cells of the first non-blank line of a CSV file, None when it
    cannot be read (``read_values`` then names the problem)."""
    try:
        with open(arg, encoding="utf-8", newline="") as handle:
            for row in csv.reader(handle):
                if any(c.strip() for c in row):
                    return [c.strip() for c in row]
    except (OSError, UnicodeDecodeError, csv.Error):
        return None
    return None


def path_rows(mech, arg: str) -> tuple[str, np.ndarray]:
    """``--path``: ``("fk", motor rows)`` or ``("bk", output rows)`` from a CSV file
    whose header names the motors or the outputs; at most ``MAX_FRAMES`` rows."""
    from .._engine.arguments import MAX_VALUE

    if not Path(arg).is_file():
        raise InputError(f"--path: {arg}: no such CSV file")
    header = _header(arg)
    motors, outputs = list(mech.motor_names), list(mech.output_names)
    if header == motors:
        kind, names, what, scale = "fk", mech.motor_names, "motors", mech.motor_scale
    elif header == outputs or header is None:
        kind, names, what = "bk", mech.output_names, "outputs"
        scale = mech.output_scale
    else:
        raise InputError(
            f"--path: {arg}: line 1 must name the motors ({','.join(motors)}) or the "
            f"outputs ({','.join(outputs)}), got {','.join(header)[:80]!r}"
        )
    values, _ = read_values(arg, names, what, MAX_VALUE * scale, MAX_ROWS)
    if len(values) > MAX_FRAMES:
        raise InputError(
            f"--path: {arg}: {len(values)} rows, more than the limit of {MAX_FRAMES} "
            "frames"
        )
    return kind, values


def _out(text: str) -> Path:
    out = Path(text)
    if out.suffix.lower() != ".gif":
        raise InputError(f"--out: {text}: expected a file name ending in .gif")
    if not out.parent.is_dir():
        raise InputError(
            f"--out: {text}: the folder {str(out.parent)!r} does not exist"
        )
    if out.is_dir():
        raise InputError(f"--out: {text}: is a folder; expected a .gif file name")
    return out


def _note_short_frames(mech, item, frames: int, design) -> None:
    """A note on the frames of the default loop that the design does not reach."""
    from .._design.motion import default_path, unreached_message

    pulled = int(np.sum(np.any(item.path != default_path(mech, frames, design), 1)))
    if pulled:
        print(
            f"note: {pulled} of {frames} frames of the default loop are out of the "
            "rest branch's reach; they were pulled in towards the rest outputs"
        )
    if item.first_unreached is not None:
        print(
            f"note: {int(np.sum(~item.reached))} frames are still out of reach and "
            f"show where the continuation stopped; the first: "
            f"{unreached_message(mech, item)}"
        )


def run_animate(args) -> int:
    out = _out(args.out)
    if args.path is not None and args.frames is not None:
        raise InputError("--frames: not with --path (each row of the CSV is a frame)")
    mech = load(args.file)
    from .._design.motion import (
        check_frames,
        motion,
        unreached_message,
    )
    from .._draw.animation import draw

    design = design_arg(mech, args.design)
    frames = check_frames(
        DEFAULT_FRAMES if args.frames is None else args.frames, "--frames"
    )
    rows = {}
    if args.path is not None:
        kind, values = path_rows(mech, args.path)
        rows = {"motors" if kind == "fk" else "outputs": values}
    item = motion(mech, design=design, frames=frames, **rows)
    if item.first_unreached is not None and args.path is not None:
        print(
            f"linkopt: error: --path {args.path}: "
            f"{unreached_message(mech, item, 'row')}",
            file=sys.stderr,
        )
        return 1
    draw(mech, item, out, design=design)
    low, high = float(np.min(item.f_sing)), float(np.max(item.f_sing))
    source = f"{args.path} ({'motor' if item.kind == 'fk' else 'output'} rows)"
    print(
        f"wrote {out}: {len(item.states)} frames along "
        f"{source if args.path else 'the default loop through the targets'}, "
        f"f_sing {low:.4g} to {high:.4g}"
    )
    if args.path is None:
        _note_short_frames(mech, item, frames, design)
    return 0


def register(subparsers) -> None:
    """Add ``animate`` to the ``linkopt`` sub-commands."""
    cmd = subparsers.add_parser(
        "animate", help="GIF of the mechanism moving along a path"
    )
    cmd.add_argument("file")
    cmd.add_argument("--out", required=True, help="the GIF to write (.gif)")
    cmd.add_argument(
        "--design",
        help="design values (comma-separated, parameter order) or a mechanism file",
    )
    cmd.add_argument(
        "--frames",
        type=int,
        default=None,
        help=f"frames of the default loop (default {DEFAULT_FRAMES}, at most "
        f"{MAX_FRAMES})",
    )
    cmd.add_argument(
        "--path",
        help=(
            "CSV file of motor or output rows (header: their names), one frame each, "
            f"at most {MAX_FRAMES}"
        ),
    )
    cmd.set_defaults(run=run_animate)
