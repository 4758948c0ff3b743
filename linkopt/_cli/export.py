"""``linkopt export FILE --format mjcf|urdf|stl|glb|dxf|svg --out PATH``: a design in
the file formats of other tools (:mod:`linkopt._export`).

Everything the user can get wrong is checked before anything is written: the design,
the file's units, a closed-loop file asked for as URDF, a spatial one as DXF or SVG,
``--thickness``, and ``--out`` (its folder is created; an unwritable one exits 2).
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

from .._errors import InputError, MechanismFileError
from .._folders import output_folder
from .values import design_arg, load

FORMATS = ("mjcf", "urdf", "stl", "glb", "dxf", "svg")


def _check_out(fmt: str, out: str) -> Path:
    """The output path, its folder created and writable; for ``stl`` a folder (not
    named ``*.stl``)."""
    path = Path(out)
    if fmt == "stl":
        if path.suffix.lower() == ".stl":
            raise InputError(
                f"--out: {out!r}: stl export writes a folder with one <body>.stl per "
                "body; give a folder path"
            )
        return output_folder(path, "--out")
    if path.is_dir():
        raise InputError(f"--out: {out!r} is a directory; expected a file path")
    output_folder(path.parent if str(path.parent) else Path("."), "--out")
    return path


def _check_stl_names(mech) -> None:
    """Each body's name is a file name in the stl folder (``<body>.stl``): one without
    a path separator or NUL (``../../x`` wrote ``x.stl`` two folders above ``--out``;
    ``a/b`` failed on the missing folder ``a``)."""
    for k, name in enumerate(mech.body_names):
        if any(c in name for c in "/\\\0"):
            raise MechanismFileError(
                mech.source,
                f"bodies[{k}].name",
                f"{name!r} cannot name a file of the stl export (one <body>.stl per "
                "body in --out): expected no '/', '\\' or NUL; "
                "rename the body, or export mjcf or glb",
            )


def _check(args, mech, design):
    from .._export.meshes import check_thickness
    from .._export.sheet import check_planar, require_ezdxf
    from .._export.tree import metres_per_unit
    from .._export.urdf import check_open_chain

    metres_per_unit(mech)
    if args.format == "urdf":
        if args.thickness is not None:
            raise InputError("--thickness: a URDF export writes no solids")
        check_open_chain(mech)
    else:
        check_thickness(mech, args.thickness)
    if args.format == "stl":
        _check_stl_names(mech)
    if args.format in ("dxf", "svg"):
        check_planar(mech, design)
    if args.format == "dxf":
        require_ezdxf()


def _export(args, mech, design, out: Path) -> dict:
    from .._export import meshes, mjcf, sheet, urdf

    if args.format == "mjcf":
        return mjcf.export_mjcf(mech, out, design, thickness=args.thickness)
    if args.format == "urdf":
        return urdf.export_urdf(mech, out, design)
    if args.format in ("dxf", "svg"):
        write = sheet.export_dxf if args.format == "dxf" else sheet.export_svg
        return write(mech, out, design, thickness=args.thickness)
    write = meshes.export_stl if args.format == "stl" else meshes.export_glb
    return write(mech, out, design, thickness=args.thickness)


def run_export(args) -> int:
    mech = load(args.file)
    design = design_arg(mech, args.design)
    _check(args, mech, design)
    out = _check_out(args.format, args.out)
    start = time.perf_counter()
    summary = _export(args, mech, design, out)
    summary = {"file": args.file, "out": str(out), **summary}
    summary["seconds"] = round(time.perf_counter() - start, 3)
    for line in summary.get("warnings", ()):
        print(f"warning: {out}: {line}", file=sys.stderr)
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        details = ", ".join(
            f"{k} {v}" for k, v in summary.items() if isinstance(v, (int, float))
        )
        print(f"wrote {summary['out']} ({args.format}: {details})")
    return 0


def register(subparsers) -> None:
    """Add ``export`` to the ``linkopt`` sub-commands."""
    cmd = subparsers.add_parser(
        "export",
        help="the design as MuJoCo MJCF, URDF, STL, GLB, or a DXF/SVG sheet drawing",
    )
    cmd.add_argument("file")
    cmd.add_argument("--format", required=True, choices=FORMATS)
    cmd.add_argument(
        "--out",
        required=True,
        help="output file; for stl a folder (one <body>.stl per body)",
    )
    cmd.add_argument(
        "--design",
        help=(
            "design values in parameter order (comma-separated), or a mechanism file "
            "with the same parameters"
        ),
    )
    cmd.add_argument(
        "--thickness",
        type=float,
        help=(
            "link diameter in file units (mjcf, stl, glb, dxf, svg; default 4%% of "
            "the reference length)"
        ),
    )
    cmd.add_argument("--json", action="store_true", help="machine-readable summary")
    cmd.set_defaults(run=run_export)
