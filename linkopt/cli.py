"""Command line: ``linkopt check | fk | bk``; a thin layer over the public API.

Bad input exits with status 2 and one line on stderr; a failed solve exits with 1.
"""

from __future__ import annotations

import argparse
import csv
import json
import sys
from pathlib import Path

import numpy as np

from . import _report
from ._errors import InputError, LinkoptError
from ._kinematics import solve_bk, solve_bk_path, solve_fk, solve_fk_path
from ._loader import load


def _parse_row(text: str, names: tuple[str, ...], where: str) -> list[float]:
    expected, what = len(names), ", ".join(names)
    cells = [c.strip() for c in text.split(",") if c.strip() != ""]
    try:
        values = [float(c) for c in cells]
    except ValueError:
        raise InputError(f"{where}: expected {expected} comma-separated numbers ({what}), got {text!r}") from None
    if len(values) != expected or not np.all(np.isfinite(values)):
        raise InputError(f"{where}: expected {expected} finite numbers ({what}), got {len(values)}: {text!r}")
    return values


def _read_values(arg: str, names: tuple[str, ...], what: str) -> tuple[np.ndarray, bool]:
    """Values from ``v1,v2,...`` or a CSV file of rows (optional header); returns (values, is_path)."""
    path = Path(arg)
    if not (arg.lower().endswith(".csv") or path.is_file()):
        return np.array(_parse_row(arg, names, f"--{what}")), False
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as err:
        raise InputError(f"{arg}: cannot read CSV file ({err.strerror})") from None
    rows = [r for r in csv.reader(lines) if any(c.strip() for c in r)]
    if rows and rows[0] and not _is_number(rows[0][0]):
        header = [c.strip() for c in rows[0]]
        if header != list(names):
            raise InputError(f"{arg}: line 1: header {header} does not match the {what} {list(names)}")
        rows = rows[1:]
    if not rows:
        raise InputError(f"{arg}: no data rows")
    values = [_parse_row(",".join(r), names, f"{arg}: row {k + 1}") for k, r in enumerate(rows)]
    return np.array(values), True


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _print_table(title: str, items: dict) -> None:
    print(title)
    for key, value in items.items():
        print(f"  {key:<18} {value}")


def _cmd_check(args) -> int:
    mech = load(args.file)
    info = _report.summary(mech)
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    print(f"{info['name']} ({info['file']}): OK")
    sizes = {k: info[k] for k in ("state_size", "mobility", "design_parameters", "reference_length")}
    sizes["constraint_rows"] = f"FK {info['constraint_rows']['fk']}, BK {info['constraint_rows']['bk']}"
    sizes["bodies"] = ", ".join(info["bodies"])
    _print_table("sizes", sizes)
    _print_table("motors", {k: f"{v['kind']} at {v['joint']}" for k, v in info["motors"].items()})
    _print_table("outputs", {k: f"{v['kind']} in [{v['min']:g}, {v['max']:g}]" for k, v in info["outputs"].items()})
    _print_table("parameters", {k: f"{v['initial']:g} in [{v['min']:g}, {v['max']:g}]" for k, v in info["parameters"].items()})
    _print_table("joints (rest anchor)", {k: f"{v['type']:<11} {v['anchor']}" for k, v in info["joints"].items()})
    return 0


def _solve_command(args, kind: str) -> int:
    mech = load(args.file)
    names = mech.motor_names if kind == "fk" else mech.output_names
    what = "motors" if kind == "fk" else "outputs"
    values, is_path = _read_values(getattr(args, what), names, what)
    if is_path:
        solver = solve_fk_path if kind == "fk" else solve_bk_path
    else:
        solver = solve_fk if kind == "fk" else solve_bk
    solution = solver(mech, values)
    states = np.atleast_2d(np.asarray(solution.state))
    converged = np.atleast_1d(np.asarray(solution.converged))
    residual = np.atleast_1d(np.asarray(solution.residual))
    records = [_report.configuration(mech, s, c, r) for s, c, r in zip(states, converged, residual)]
    payload = {"converged": bool(converged.all()), "path": records} if is_path else records[0]
    if args.json:
        print(json.dumps(payload, indent=2))
    else:
        for k, rec in enumerate(records):
            label = f"row {k + 1}" if is_path else kind.upper()
            print(f"{label}: converged={rec['converged']} residual={rec['residual']:.2e} f_sing={rec['f_sing']:.4g} (σ_min FK {rec['sigma_min_fk']:.4g}, BK {rec['sigma_min_bk']:.4g})")
            print("  motors  " + ", ".join(f"{n}={v:.6g}" for n, v in rec["motors"].items()))
            print("  outputs " + ", ".join(f"{n}={v:.6g}" for n, v in rec["outputs"].items()))
            if not is_path:
                for n, p in {**rec["joints"], **rec["points"]}.items():
                    print(f"  {n:<16} ({p[0]:.6g}, {p[1]:.6g}, {p[2]:.6g})")
    if not converged.all():
        first = int(np.argmin(converged))
        where = f" at row {first + 1}" if is_path else ""
        print(f"linkopt: error: {kind.upper()} solve failed{where}: residual {residual[first]:.2e} (no assembly reached from the start state)", file=sys.stderr)
        return 1
    return 0


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="linkopt", description="Singularity-aware design of closed-loop spatial linkages.")
    sub = parser.add_subparsers(dest="command", required=True)
    check = sub.add_parser("check", help="validate a mechanism file and summarise it")
    check.add_argument("file")
    check.add_argument("--json", action="store_true", help="machine-readable output")
    check.set_defaults(run=_cmd_check)
    for kind, what, text in (("fk", "motors", "forward kinematics: motor values -> configuration"), ("bk", "outputs", "backward kinematics: outputs -> configuration and motors")):
        cmd = sub.add_parser(kind, help=text)
        cmd.add_argument("file")
        cmd.add_argument(f"--{what}", required=True, help=f"comma-separated {what} (file units, radians), or a CSV file of rows solved as one continuation path")
        cmd.add_argument("--json", action="store_true", help="machine-readable output")
        cmd.set_defaults(run=lambda a, k=kind: _solve_command(a, k))
    return parser


def _join_value_options(argv: list[str]) -> list[str]:
    """``--motors -0.1,0.2`` -> ``--motors=-0.1,0.2`` so negative values are not options."""
    joined: list[str] = []
    pending = False
    for token in argv:
        if pending and token.startswith("-"):
            joined[-1] = f"{joined[-1]}={token}"
        else:
            joined.append(token)
        pending = token in ("--motors", "--outputs")
    return joined


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    args = _parser().parse_args(_join_value_options(list(argv)))
    try:
        return args.run(args)
    except LinkoptError as err:
        print(f"linkopt: error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
