"""``linkopt verify``: one design of a mechanism file, the file's own or ``--design``,
checked densely over the target range: coverage, singularity distance and, with
``[collision]``, link clearance. Exits with 1 when the design fails the check.
"""

from __future__ import annotations

import json

from .._errors import InputError
from .grids import add_max_cells
from .values import design_arg, load


def verification_payload(mech, result) -> dict:
    """What ``linkopt verify`` reports (``--json``) for one verification."""
    from .payloads import verified_limits

    return {
        "passed": result.passed,
        "coverage": result.coverage,
        "cells": result.cells,
        "grid": list(result.grid_shape),
        "threshold_alpha_minus": result.threshold,
        "max_f_sing": result.max_f_sing,
        "min_sigma_fk": result.min_sigma_fk,
        "min_sigma_bk": result.min_sigma_bk,
        "worst_cell": dict(zip(mech.output_names, map(float, result.worst_outputs))),
        "unreached_example": None
        if result.unreached_example is None
        else dict(zip(mech.output_names, map(float, result.unreached_example))),
        **_verified_collision(mech, result),
        **verified_limits(mech, result),
    }


def _verified_collision(mech, result) -> dict:
    """``verify --json``'s ``collision`` entry, only for a file that checks them."""
    if result.min_clearance is None:
        return {}
    cell = result.collision_outputs
    return {
        "collision": {
            "clearance": mech.collision.clearance,
            "min_clearance": result.min_clearance,
            "pair": None
            if result.collision_pair is None
            else list(result.collision_pair),
            "cell": None
            if cell is None
            else dict(zip(mech.output_names, map(float, cell))),
        }
    }


def run_verify(args) -> int:
    if args.resolution is not None and args.resolution < 2:
        raise InputError(
            "--resolution: expected at least 2 points per output, "
            f"got {args.resolution}"
        )
    mech = load(args.file)
    from .._design.maps import check_count
    from .._design.verify import check_resolution, verify

    design = design_arg(mech, args.design)
    max_cells = check_count(args.max_cells, "--max-cells", 1)
    resolution = check_resolution(
        mech,
        args.resolution,
        max_cells=max_cells,
        where="--resolution",
        raise_with="--max-cells",
    )
    result = verify(mech, design, resolution, max_cells=max_cells)
    payload = verification_payload(mech, result)
    if args.json:
        print(json.dumps(payload, indent=2))
    else:
        _print_verification(mech, payload)
    return 0 if payload["passed"] else 1


def _print_verification(mech, payload: dict) -> None:
    verdict = "PASS" if payload["passed"] else "FAIL"
    print(
        f"{mech.name}: {verdict}: coverage {100 * payload['coverage']:.1f}% of "
        f"{payload['cells']} cells; max f_sing {payload['max_f_sing']:.4g} "
        f"(threshold α₋ {payload['threshold_alpha_minus']:.4g}); "
        f"min σ FK {payload['min_sigma_fk']:.3g}, BK {payload['min_sigma_bk']:.3g}"
    )
    print(
        "  worst cell "
        + ", ".join(f"{n}={v:.4g}" for n, v in payload["worst_cell"].items())
    )
    if payload["unreached_example"]:
        print(
            "  e.g. unreached "
            + ", ".join(f"{n}={v:.4g}" for n, v in payload["unreached_example"].items())
        )
    if "collision" in payload:
        print("  " + _collision_line(payload["collision"]))
    if "motor_limits" in payload:
        from .payloads import limits_line

        print("  " + limits_line(payload["motor_limits"]))


def _collision_line(entry: dict) -> str:
    """One line on the least clearance of a verification (file units)."""
    if entry["pair"] is None:
        return f"collision: no checked pair in a reached cell ({entry['clearance']:g})"
    closer = entry["min_clearance"] < entry["clearance"]
    a, b = entry["pair"]
    cell = ", ".join(f"{n}={v:.4g}" for n, v in entry["cell"].items())
    return (
        f"collision: {'FAIL' if closer else 'clear'}: {a} and {b} "
        f"{entry['min_clearance']:.4g} apart at {cell} (clearance "
        f"{entry['clearance']:.4g}{'; closer than it' if closer else ''})"
    )


def register(subparsers) -> None:
    """Add ``verify`` to the ``linkopt`` sub-commands."""
    verify_cmd = subparsers.add_parser(
        "verify",
        help=(
            "dense check of the whole target range: coverage and singularity "
            "distance (and link clearance, with [collision])"
        ),
    )
    verify_cmd.add_argument("file")
    verify_cmd.add_argument("--design", help="as for evaluate")
    verify_cmd.add_argument(
        "--resolution",
        type=int,
        help="grid points per output (default 41, or 13 for 3 outputs)",
    )
    add_max_cells(verify_cmd)
    verify_cmd.add_argument(
        "--json", action="store_true", help="machine-readable output"
    )
    verify_cmd.set_defaults(run=run_verify)
