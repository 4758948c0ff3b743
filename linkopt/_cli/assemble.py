"""``linkopt assemble FILE --out FILE2``: solve a drawn mechanism's loop closures.

The file gives approximate anchors and declared dimensions (``[[lengths]]``, bodies in
their own frame; :mod:`linkopt._files.assembly`); the command writes the assembled
file (world anchors to full precision, an ordinary mechanism file that every command
reads) and reports how far each anchor moved, the declared lengths as assembled, how
far each prismatic or cylindrical joint slid, and σ_min at the assembled rest pose,
with a warning when that pose is near a singularity.
Nothing is written when the loops do not close or the assembled file would not pass
``linkopt check`` (the error says so); a missing folder of ``--out`` is made, as every
command's ``--out`` does, once the file can be written.
"""

from __future__ import annotations

import copy
import json
import sys
from pathlib import Path

import numpy as np

from .._errors import InputError, LinkoptError
from .._files.fields import parse_text
from .._folders import write_atomic
from .values import parse_row


def run_assemble(args) -> int:
    source, out = Path(args.file), Path(args.out)
    if out.exists() and out.resolve() == source.resolve():
        raise InputError(
            f"--out: {args.out!r} is the input file; give another path (the "
            "assembled file has no [[lengths]] or body frames left)"
        )
    if out.is_dir():
        raise InputError(f"--out: {args.out!r} is a folder; expected a file path")
    data = parse_text(source)
    motors = _motor_values(args.motors, data)
    from .._engine.geometry import rest_state
    from .._engine.mobility import check_mobility
    from .._engine.singularity import singular_values
    from .._files.assembly import assemble
    from .._files.loader import build
    from .._files.writer import dumps

    try:
        result = assemble(data, str(source), motors)
        mech = build(copy.deepcopy(result.data), str(out), check=False)
        sigma_fk, sigma_bk = (float(v) for v in singular_values(mech, rest_state(mech)))
        check_mobility(mech)
    except LinkoptError as err:
        raise InputError(f"{err} ({out} was not written)") from err
    # a missing folder is made, as every command's --out does, once there is a file
    out.parent.mkdir(parents=True, exist_ok=True)
    write_atomic(out, _header(source, result.report) + dumps(result.data))
    payload = _payload(source, out, result.report, sigma_fk, sigma_bk)
    if args.json:
        print(json.dumps(payload, indent=2))
    else:
        _print_report(payload)
    for warning in payload["warnings"]:
        print(f"linkopt: warning: {warning}", file=sys.stderr)
    return 0


def _motor_values(text: str | None, data: dict) -> np.ndarray | None:
    """``--motors v1,v2,…``: one value per ``[[motors]]`` entry, in file order."""
    if text is None:
        return None
    motors = data.get("motors", [])
    names = tuple(
        str(m.get("name", f"motors[{k}]")) if isinstance(m, dict) else f"motors[{k}]"
        for k, m in enumerate(motors if isinstance(motors, list) else [])
    )
    return np.array(parse_row(text, names, "--motors"))


def _header(source: Path, report) -> str:
    """The source's leading comment, then where the file came from and what was
    held."""
    lines = []
    for line in source.read_text(encoding="utf-8").splitlines():
        if not line.startswith("#"):
            break
        lines.append(line)
    lines.append(f"# Assembled by `linkopt assemble` from {source.name}.")
    if report.lengths:
        held = ", ".join(f"{i}–{j} = {d:g}" for (i, j), d, _ in report.lengths)
        lines.append(f"# Declared lengths ({report.units}), held exactly: {held}.")
    return "\n".join(lines) + "\n\n"


def _payload(source: Path, out: Path, report, sigma_fk: float, sigma_bk: float):
    from .._files.assembly import NEAR_SINGULAR

    warnings = []
    if not sigma_fk >= NEAR_SINGULAR:  # NaN too
        warnings.append(
            f"the assembled rest pose is near a forward singularity (σ_min FK "
            f"{sigma_fk:.3g} < {NEAR_SINGULAR:g}): choose other --motors or redraw"
        )
    if not sigma_bk >= NEAR_SINGULAR:  # NaN too
        warnings.append(
            f"the assembled rest pose is near a backward singularity (σ_min BK "
            f"{sigma_bk:.3g} < {NEAR_SINGULAR:g})"
        )
    return {
        "file": str(source),
        "out": str(out),
        "units": report.units,
        "moves": [
            {
                "joint": m.joint,
                "before": list(m.before),
                "after": list(m.after),
                "distance": m.distance,
            }
            for m in report.moves
        ],
        "largest_move": report.largest_move,
        "lengths": [
            {"joints": list(pair), "declared": d, "assembled": a}
            for pair, d, a in report.lengths
        ],
        "slides": [
            {"joint": j, "drawn": d, "assembled": a} for j, d, a in report.slides
        ],
        "residual": report.residual,
        "sigma_min_fk": sigma_fk,
        "sigma_min_bk": sigma_bk,
        "near_singular": bool(warnings),
        "warnings": warnings,
    }


def _print_report(payload: dict) -> None:
    units = payload["units"]
    print(f"{payload['file']}: assembled -> {payload['out']}")
    print(f"  {'joint':<16} {'drawn':<36} {'assembled':<36} moved ({units})")
    for m in payload["moves"]:
        before = "(" + ", ".join(f"{v:.6g}" for v in m["before"]) + ")"
        after = "(" + ", ".join(f"{v:.6g}" for v in m["after"]) + ")"
        print(f"  {m['joint']:<16} {before:<36} {after:<36} {m['distance']:.6g}")
    for item in payload["lengths"]:
        i, j = item["joints"]
        print(
            f"  length {i}–{j}: declared {item['declared']:g}, assembled "
            f"{item['assembled']!r}"
        )
    for item in payload["slides"]:
        drawn, assembled = (_clean(item[k]) for k in ("drawn", "assembled"))
        print(
            f"  slide {item['joint']}: drawn {drawn:.6g}, assembled {assembled:.6g} "
            f"{units} (moved {_clean(assembled - drawn):+.6g})"
        )
    print(
        f"  largest move {payload['largest_move']:.6g} {units}; residual "
        f"{payload['residual']:.2e} {units}; σ_min at rest: FK "
        f"{payload['sigma_min_fk']:.4g}, BK {payload['sigma_min_bk']:.4g}"
    )


def _clean(value: float) -> float:
    """A slide shown as 0 below 1e-9 file units (the solve's rounding)."""
    return value if abs(value) > 1e-9 else 0.0


def register(subparsers) -> None:
    """Add ``assemble`` to the ``linkopt`` sub-commands."""
    cmd = subparsers.add_parser(
        "assemble",
        help="solve a drawn mechanism's loops (approximate anchors, declared lengths)",
    )
    cmd.add_argument("file")
    cmd.add_argument("--out", required=True, help="the assembled mechanism file")
    cmd.add_argument(
        "--motors",
        help=(
            "comma-separated motor values (rad, file units) to turn the motors by "
            "from the drawing before assembling; the assembled pose is motor zero"
        ),
    )
    cmd.add_argument("--json", action="store_true", help="machine-readable output")
    cmd.set_defaults(run=run_assemble)
