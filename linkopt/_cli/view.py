"""``linkopt view FILE [--design DESIGN] [--out view.html] [--resolution N]``: one
self-contained HTML page that moves a mechanism through its configurations
(:mod:`linkopt._draw.view`).

``FILE`` is a mechanism file or an ``optimize`` run folder (its ``optimized.toml``;
the page toggles the initial and the optimised design). Everything the user can get
wrong is checked before any solve: the design (a mechanism file given as ``--design``
must have the same bodies, joints and parameters), ``--resolution`` against the page's
budget (the message says what it would cost), and ``--out`` (its folder must exist and
be writable; nothing is created).
"""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

import numpy as np

from .._errors import InputError, LinkoptError
from .values import design_arg, load

#: The page's name in a run folder (``linkopt optimize`` writes it there too).
VIEW_FILE = "view.html"


def check_out(out: str) -> Path:
    """``--out``: a file path in an existing, writable folder."""
    path = Path(out)
    folder = path.parent if str(path.parent) else Path(".")
    if path.is_dir():
        raise InputError(f"--out: {out!r} is a directory; expected an HTML file path")
    if not folder.is_dir():
        raise InputError(f"--out: {out!r}: the folder {str(folder)!r} does not exist")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise InputError(f"--out: {out!r}: the folder {str(folder)!r} is not writable")
    return path


def _same_mechanism(mech, text: str) -> None:
    """A mechanism file given as ``--design`` has ``mech``'s bodies and joints."""
    other = load(text)
    for what in ("body_names", "joint_names"):
        if getattr(other, what) != getattr(mech, what):
            kind = what.split("_")[0]
            raise InputError(
                f"--design: {text}: its {kind}s {list(getattr(other, what))} are not "
                f"those of {mech.source}: {list(getattr(mech, what))}; expected a "
                "design of the same mechanism"
            )


def run_designs(folder: Path):
    """The mechanism of a run folder (its ``optimized.toml``) and its designs:
    ``[("initial", p0), ("optimised", p)]`` (``summary.json``'s initial design; a
    ``synthesize`` folder's too)."""
    optimized, summary = folder / "optimized.toml", folder / "summary.json"
    if not optimized.is_file() or not summary.is_file():
        raise InputError(
            f"{folder}: a folder is viewed as an optimize run folder, but it has no "
            "optimized.toml and summary.json"
        )
    mech = load(optimized)
    try:
        initial = json.loads(summary.read_text())["initial_design"]
        p0 = np.array([float(initial[n]) for n in mech.design.names])
    except (ValueError, KeyError, TypeError) as err:
        raise InputError(
            f"{summary}: initial_design: expected a value for each of "
            f"{list(mech.design.names)} ({type(err).__name__}: {err})"
        ) from None
    return mech, [("initial", p0), ("optimised", np.asarray(mech.design.p0))]


def _designs(args):
    path = Path(args.file)
    if path.is_dir():
        if args.design is not None:
            raise InputError("--design: a run folder's page shows its own two designs")
        mech, designs = run_designs(path)
        return mech, designs, path / VIEW_FILE
    mech = load(args.file)
    if args.design is not None and args.design.lower().endswith(".toml"):
        if Path(args.design).is_file():
            _same_mechanism(mech, args.design)
    design = design_arg(mech, args.design)
    label = "file's design" if design is None else f"design {args.design}"
    return mech, [(label, design)], Path(VIEW_FILE)


def write_page(mech, designs, out: Path, resolution, progress=None) -> dict:
    """:func:`linkopt._draw.view.write_page`, imported when called: building the
    parser imports no JAX (:mod:`linkopt._cli.main`)."""
    from .._draw.view import write_page as write

    return write(mech, designs, out, resolution, progress)


def write_run_view(out: Path) -> None:
    """``view.html`` in a run folder (``optimize``, ``synthesize``), beside the
    figures: the run's initial and final designs, at the default resolution. One it
    cannot write is a warning: the run's results stand."""
    try:
        mech, designs = run_designs(out)
        write_page(mech, designs, out / VIEW_FILE, None)
    except (LinkoptError, ImportError) as err:
        print(
            f"linkopt: warning: {out / VIEW_FILE} not written: {err}", file=sys.stderr
        )


def run_view(args) -> int:
    mech, designs, default = _designs(args)
    out = check_out(args.out if args.out is not None else str(default))
    from .._design.view_grid import check_view_grid

    check_view_grid(mech, args.resolution, len(designs))

    def progress(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    summary = write_page(mech, designs, out, args.resolution, progress)
    reached = ", ".join(f"{k} {v}" for k, v in summary["reached"].items())
    print(
        f"wrote {summary['out']} ({summary['bytes'] / 1e6:.2f} MB; "
        f"{summary['resolution']} cells per motor, {summary['cells']} configurations; "
        f"reached: {reached})"
    )
    return 0


def register(subparsers) -> None:
    """Add ``view`` to the ``linkopt`` sub-commands."""
    cmd = subparsers.add_parser(
        "view",
        help="an offline HTML page: drag the motors, see f_sing and the clearance",
    )
    cmd.add_argument("file", help="a mechanism file, or an optimize run folder")
    cmd.add_argument(
        "--design",
        help=(
            "design values in parameter order (comma-separated), or a mechanism file "
            "of the same mechanism"
        ),
    )
    cmd.add_argument(
        "--out",
        help="the HTML file (default view.html; in a run folder, the folder's)",
    )
    cmd.add_argument(
        "--resolution",
        type=int,
        help="grid cells per motor (default: the finest whose page stays small)",
    )
    cmd.set_defaults(run=run_view)
