"""``linkopt check | fk | bk``: a mechanism file, its summary and its kinematics.

``fk``/``bk`` solve one configuration from ``--motors``/``--outputs`` values, or a CSV
file of rows solved as one continuation path; a failed solve exits with 1.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from .values import MAX_ROWS, at_design, design_arg, load, read_values


def _print_table(title: str, items: dict) -> None:
    print(title)
    for key, value in items.items():
        print(f"  {key:<18} {value}")


def run_check(args) -> int:
    """Exit 0 for a valid file, warnings included: a rest pose near a singularity is
    a valid mechanism (the file may set ``alpha_minus``), so it is said, not
    refused. With ``--design``, the file at that design (:func:`.values.at_design`)."""
    mech = load(args.file)
    design = design_arg(mech, args.design)
    mech = at_design(mech, design)
    from . import payloads

    info = payloads.summary(mech)
    if design is not None:
        info["design"] = dict(zip(mech.design.names, map(float, design)))
    info["rest_pose"], warnings = _rest_pose(mech)
    info["warnings"] = warnings
    moves = moved_points(mech)
    info["moved_points"] = [m.as_json(mech.design.names) for m in moves]
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    count = f" with {len(warnings)} warning(s)" if warnings else ""
    at = ""
    if "design" in info:
        at = " at design " + ", ".join(f"{k}={v:g}" for k, v in info["design"].items())
    print(f"{info['name']} ({info['file']}){at}: OK{count}")
    _print_summary(info)
    if info["idle_spins"]:
        print(
            f"{len(info['idle_spins'])} idle spin(s): {', '.join(info['idle_spins'])} "
            "spin about their own axis; fixed by a gauge constraint"
        )
    _print_collision(info["collision"])
    if info["welded"]:
        print(
            f"{len(info['welded'])} welded part(s), one body with the part they are "
            "welded to: " + ", ".join(f"{k} on {v}" for k, v in info["welded"].items())
        )
    print_moves(mech, moves, "over the design box")
    _print_rest_pose(info["rest_pose"])
    for line in warnings:
        print(f"linkopt: warning: {line}", file=sys.stderr)
    return 0


def moved_points(mech, design=None) -> tuple:
    """The named points a design moves far on their bodies
    (:mod:`linkopt._engine.point_moves`): over the design box, or at ``design``."""
    from .._engine.point_moves import box_designs, point_moves

    return point_moves(mech, box_designs(mech) if design is None else design)


def print_moves(mech, moves, where: str) -> None:
    """One line per point a design moves far, under a title naming ``where``."""
    from .._engine.point_moves import MOVE_SHARE

    if moves:
        units = mech.raw.get("mechanism", {}).get("units", "")
        print(
            f"{len(moves)} point(s) moved by more than {100 * MOVE_SHARE:g} % of "
            f"their body's anchor span {where}:"
        )
        for move in moves:
            print(f"  {move.line(units)}")


def _rest_pose(mech) -> tuple[dict, list[str]]:
    """The rest pose's conditioning (homogenised σ_min and f_sing, and the singular
    values of the textbook Jacobian ∂b/∂a in file units) and the warnings about it."""
    from .._design.conditioning import near_singular_message, rest_conditioning

    rest = rest_conditioning(mech)
    info = rest.as_json()
    warnings = []
    if rest.near_singular:
        fixed = mech.evaluation.alpha_minus is not None
        warnings.append(
            near_singular_message(mech, rest).split(", so ")[0]
            + (
                f"; alpha_minus = {mech.evaluation.alpha_minus:g} is set, f_sing "
                "along the target range is judged by it"
                if fixed
                else "; evaluate, verify and optimize refuse to derive α₋ from it: "
                "set [evaluation] alpha_minus"
            )
        )
    return info, warnings


def _print_collision(collision: dict | None) -> None:
    """``[collision]``'s line of ``check``: off when the file has none."""
    if collision is None:
        print("collision: off (no [collision] table)")
        return
    state = "on" if collision["enabled"] else "off (enable = false)"
    pairs = ", ".join("-".join(p) for p in collision["pairs"]) or "none"
    print(
        f"collision: {state}, clearance {collision['clearance']:g} (file units), "
        f"weight {collision['weight']:g}, {len(collision['pairs'])} checked pair(s) "
        f"({pairs}; {collision['capsule_pairs']} capsule pair(s) of "
        f"{collision['capsules']} capsules), {collision['layers']} layer(s)"
    )


def _print_rest_pose(rest: dict) -> None:
    _print_table(
        "rest pose",
        {
            "σ_min FK, BK": f"{rest['sigma_min_fk']:.4g}, {rest['sigma_min_bk']:.4g} "
            f"(homogenised; f_sing {rest['f_sing']:.4g})",
            "∂b/∂a σ min, max": f"{rest['jacobian_sigma_min']:.4g}, "
            f"{rest['jacobian_sigma_max']:.4g} (file units)",
        },
    )


def _limits(motor: dict) -> str:
    """A motor's limits as ``check`` prints them (empty without any): unlimited sides
    as ±inf."""
    if "min" not in motor and "max" not in motor:
        return ""
    low, high = motor.get("min", -float("inf")), motor.get("max", float("inf"))
    return f", limits [{low:g}, {high:g}]"


def _print_summary(info: dict) -> None:
    """The tables of ``linkopt check``: sizes, motors, outputs, parameters, joints."""
    sizes = {
        k: info[k]
        for k in ("state_size", "mobility", "design_parameters", "reference_length")
    }
    sizes["constraint_rows"] = (
        f"FK {info['constraint_rows']['fk']}, BK {info['constraint_rows']['bk']}"
    )
    sizes["bodies"] = ", ".join(info["bodies"])
    _print_table("sizes", sizes)
    _print_table(
        "motors",
        {
            k: f"{v['kind']} at {v['joint']}{_limits(v)}"
            for k, v in info["motors"].items()
        },
    )
    _print_table(
        "outputs",
        {
            k: f"{v['kind']} in [{v['min']:g}, {v['max']:g}]"
            for k, v in info["outputs"].items()
        },
    )
    if info["reported"]:
        _print_table(
            "reported outputs", {k: v["kind"] for k, v in info["reported"].items()}
        )
    _print_table(
        "parameters",
        {
            k: f"{v['initial']:g} in [{v['min']:g}, {v['max']:g}]"
            for k, v in info["parameters"].items()
        },
    )
    _print_table(
        "joints (rest anchor)",
        {k: f"{v['type']:<11} {v['anchor']}" for k, v in info["joints"].items()},
    )


def run_solve(args, kind: str) -> int:
    """``linkopt fk`` (``kind`` "fk") or ``linkopt bk`` ("bk")."""
    mech = load(args.file)
    from .._design.maps import check_count
    from .._engine.arguments import MAX_VALUE
    from .._engine.kinematics import (
        solve_bk,
        solve_bk_path,
        solve_fk,
        solve_fk_path,
    )
    from . import payloads

    names = mech.motor_names if kind == "fk" else mech.output_names
    what = "motors" if kind == "fk" else "outputs"
    scale = mech.motor_scale if kind == "fk" else mech.output_scale
    max_rows = check_count(args.max_rows, "--max-rows", 1)
    values, is_path = read_values(
        getattr(args, what), names, what, MAX_VALUE * scale, max_rows
    )
    if is_path:
        solver = solve_fk_path if kind == "fk" else solve_bk_path
    else:
        solver = solve_fk if kind == "fk" else solve_bk
    design = design_arg(mech, args.design)
    solution = solver(mech, values, design=design)
    states = np.atleast_2d(np.asarray(solution.state))
    converged = np.atleast_1d(np.asarray(solution.converged))
    residual = np.atleast_1d(np.asarray(solution.residual))
    progress = np.atleast_1d(np.asarray(solution.progress))
    records = [
        payloads.configuration(mech, s, c, r, design)
        | {"progress": float(f), "closure": payloads.closure(mech, s, design)}
        for s, c, r, f in zip(states, converged, residual, progress)
    ]
    for record, row in zip(records, np.atleast_2d(values)):
        reached = np.array(list(record[what].values()))
        record["miss"] = _miss(mech, kind, reached, row)
    payload = (
        {"converged": bool(converged.all()), "path": records} if is_path else records[0]
    )
    if args.json:
        print(json.dumps(payload, indent=2))
    else:
        _print_records(records, kind, is_path)
    if not converged.all():
        spans = _spans(mech, kind, np.atleast_2d(values), design, scale)
        _report_failure(kind, is_path, records, spans)
        return 1
    return 0


def _spans(mech, kind: str, rows: np.ndarray, design, scale) -> np.ndarray:
    """How far each row lies from where its continuation starts (the rest pose's
    values, then the previous row), homogenised: the largest ``|Δ| / scale``."""
    from .._engine.geometry import rest_state
    from .._engine.readout import output_values

    if kind == "fk":
        rest = np.zeros(rows.shape[1])
    else:
        rest = np.asarray(output_values(mech, rest_state(mech), design=design))
    starts = np.vstack([rest[None], rows[:-1]])
    return np.max(np.abs(rows - starts) / np.asarray(scale), axis=1)


def _miss(mech, kind: str, reached: np.ndarray, asked: np.ndarray) -> float:
    """Largest ``|reached - asked|``, angles compared modulo 2π (file units)."""
    from .._engine.model import OUTPUT_KINDS

    if kind == "fk":
        angular = ~np.asarray(mech.motor_linear, dtype=bool)
    else:
        angular = np.array([not OUTPUT_KINDS[k] for k in mech.output_kinds], bool)
    gap = reached - asked
    gap = np.where(angular, (gap + np.pi) % (2 * np.pi) - np.pi, gap)
    return float(np.max(np.abs(gap), initial=0.0))


def _print_records(records: list[dict], kind: str, is_path: bool) -> None:
    what = "motors" if kind == "fk" else "outputs"
    for k, rec in enumerate(records):
        label = f"row {k + 1}" if is_path else kind.upper()
        miss = "" if rec["converged"] else f" {what} miss={rec['miss']:.3g}"
        print(
            f"{label}: converged={rec['converged']} closure={rec['closure']:.2e}"
            f"{miss} f_sing={rec['f_sing']:.4g} (σ_min FK {rec['sigma_min_fk']:.4g}, "
            f"BK {rec['sigma_min_bk']:.4g})"
        )
        print(
            "  motors  " + ", ".join(f"{n}={v:.6g}" for n, v in rec["motors"].items())
        )
        print(
            "  outputs " + ", ".join(f"{n}={v:.6g}" for n, v in rec["outputs"].items())
        )
        if rec["reported"]:
            print(
                "  reported "
                + ", ".join(f"{n}={v:.6g}" for n, v in rec["reported"].items())
            )
        if not is_path:
            for n, p in {**rec["joints"], **rec["points"]}.items():
                print(f"  {n:<16} ({p[0]:.6g}, {p[1]:.6g}, {p[2]:.6g})")


def _report_failure(
    kind: str, is_path: bool, records: list[dict], spans: np.ndarray
) -> None:
    """One line: where the continuation stopped on the rest pose's branch, and why
    when it ran out of steps (``spans``: each row's distance from its start, as
    :func:`_spans`)."""
    from .._engine.continuation import MAX_STEP, MAX_STEPS

    first = next(k for k, rec in enumerate(records) if not rec["converged"])
    record = records[first]
    where = f" at row {first + 1}" if is_path else ""
    origin = "the previous row" if is_path and first > 0 else "the rest pose"
    values = record["motors"] if kind == "fk" else record["outputs"]
    what = "motors" if kind == "fk" else "outputs"
    reached = ", ".join(f"{n}={v:.6g}" for n, v in values.items())
    reach = MAX_STEPS * MAX_STEP
    why = "no assembly past it on this branch, or a singularity"
    if record["progress"] * spans[first] >= reach * (1 - 1e-9):  # out of steps
        why = (
            f"a solve takes at most {MAX_STEPS} continuation steps of {MAX_STEP:g}, "
            f"so it moves at most {reach:g} rad or reference lengths from "
            f"{origin}: give intermediate rows in a CSV path"
        )
    print(
        f"linkopt: error: {kind.upper()} solve failed{where}: the rest pose's assembly "
        f"branch stops at {reached}, {100 * record['progress']:.0f} % of the way from "
        f"{origin} ({why}); the {what} printed miss those asked by up to "
        f"{record['miss']:.3g}, and the state printed closes its loops to "
        f"{record['closure']:.1e}",
        file=sys.stderr,
    )


def _run_fk(args) -> int:
    return run_solve(args, "fk")


def _run_bk(args) -> int:
    return run_solve(args, "bk")


def register(subparsers) -> None:
    """Add ``check``, ``fk`` and ``bk`` to the ``linkopt`` sub-commands."""
    check = subparsers.add_parser(
        "check", help="validate a mechanism file and summarise it"
    )
    check.add_argument("file")
    check.add_argument(
        "--design",
        help=(
            "design values in parameter order (comma-separated), or a mechanism file "
            "with the same parameters: summarise the file at that design"
        ),
    )
    check.add_argument("--json", action="store_true", help="machine-readable output")
    check.set_defaults(run=run_check)
    for kind, what, text, run in (
        ("fk", "motors", "forward kinematics: motor values -> configuration", _run_fk),
        (
            "bk",
            "outputs",
            "backward kinematics: outputs -> configuration and motors",
            _run_bk,
        ),
    ):
        cmd = subparsers.add_parser(kind, help=text)
        cmd.add_argument("file")
        cmd.add_argument(
            f"--{what}",
            required=True,
            help=(
                f"comma-separated {what} (file units, radians), or a CSV file of rows "
                "solved as one continuation path"
            ),
        )
        cmd.add_argument(
            "--max-rows",
            type=int,
            default=MAX_ROWS,
            help=f"refuse a CSV file of more rows (default {MAX_ROWS})",
        )
        cmd.add_argument(
            "--design",
            help=(
                "design values in parameter order (comma-separated), or a mechanism "
                "file with the same parameters (default: the file's design)"
            ),
        )
        cmd.add_argument("--json", action="store_true", help="machine-readable output")
        cmd.set_defaults(run=run)
