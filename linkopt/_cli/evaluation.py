"""``linkopt evaluate | plot``: one design of a mechanism file, the file's own or
``--design``, scored (paper Sec. IV) and drawn (``verify`` checks it densely:
:mod:`.verify`).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from .._errors import InputError
from .._folders import output_folder
from .grids import add_max_cells, map_progress
from .mechanism import moved_points, print_moves
from .values import design_arg, load

_DESIGN_HELP = (
    "design values in parameter order (comma-separated), or a mechanism file with "
    "the same parameters"
)


def evaluate(mech, design):
    """:func:`linkopt.evaluate`, its module imported on the first call."""
    from .._design.evaluation import evaluate

    return evaluate(mech, design)


def _motors(mech, motors) -> dict:
    """An evaluation's (homogenised) motor values in file units, by name."""
    return dict(
        zip(mech.motor_names, map(float, np.asarray(motors) * mech.motor_scale))
    )


def _sample(mech, ev, t: int, goal, ik_out, adv_out) -> dict:
    """Target ``t``: its IK solve and its adversarial sample."""
    return {
        "target": dict(zip(mech.output_names, map(float, goal))),
        "ik": {
            "motors": _motors(mech, ev.ik_motors[t]),
            "reached": dict(zip(mech.output_names, map(float, ik_out[t]))),
            "f_bk": float(ev.ik_reach[t]),
            "f_sing": float(ev.ik_f_sing[t]),
        },
        "adversarial": {
            "motors": _motors(mech, ev.adv_motors[t]),
            "outputs": dict(zip(mech.output_names, map(float, adv_out[t]))),
            "f_sing": float(ev.adv_f_sing[t]),
            "culled": float(ev.adv_culled[t]),
        },
    }


def evaluation_payload(mech, ev, design=None) -> dict:
    """What ``linkopt evaluate`` reports (``--json``) for one evaluation of
    ``design`` (file units, None: the file's)."""
    from .._design.conditioning import rest_conditioning
    from .._design.evaluation import alpha_minus, capped, targets
    from .._design.on_bounds import on_bounds
    from .._engine.readout import output_values
    from .payloads import held_at_limits

    ik_out = np.asarray(output_values(mech, ev.ik_states, design=design))
    adv_out = np.asarray(output_values(mech, ev.adv_states, design=design))
    samples = [
        _sample(mech, ev, t, goal, ik_out, adv_out)
        for t, goal in enumerate(targets(mech))
    ]
    return {
        "f_design": float(ev.f_design),
        "reach": float(ev.reach),
        "singularity": float(ev.singularity),
        "regularizer": float(ev.regularizer),
        "alpha_minus": alpha_minus(mech),
        "rest_pose": rest_conditioning(mech).as_json(),
        "capped_samples": dict(zip(("ik", "adversarial"), capped(mech, ev))),
        "at_bounds": on_bounds(mech, design),
        "samples": samples,
        **_evaluated_collision(mech, ev, design),
        **held_at_limits(mech, ev),
    }


def _evaluated_collision(mech, ev, design) -> dict:
    """``evaluate --json``'s ``collision`` entry, only for a file that checks them:
    the collision term (the mean over the IK and collision sample states of the
    barrier, :mod:`linkopt._engine.collision`), its share of ``f_design`` (``weight``
    times it), and the least clearance with its pair and pose."""
    from .._design.collision import sample_clearance
    from .._engine.collision import has_collision, pair_names
    from .._engine.readout import output_values

    if not has_collision(mech):
        return {}
    result = sample_clearance(mech, ev, design)
    term = float(np.mean(result.value))
    entry = {
        "term": term,
        "weight": mech.collision.weight,
        "share": mech.collision.weight * term,
        "clearance": mech.collision.clearance,
        "min_clearance": float(np.min(result.minimum)),
        "pair": None,
        "pose": None,
    }
    if len(result.minimum) and result.worst[0] >= 0:
        k = int(np.argmin(result.minimum))
        count = len(ev.ik_states)
        kind, t = ("ik", k) if k < count else ("collision", k - count)
        motors = (ev.ik_motors if kind == "ik" else ev.col_motors)[t]
        state = (ev.ik_states if kind == "ik" else ev.col_states)[t]
        outputs = np.asarray(output_values(mech, state, design=design))
        entry["pair"] = list(pair_names(mech, result.worst[k]))
        entry["pose"] = {
            "sample": kind,
            "target": t,
            "motors": _motors(mech, motors),
            "outputs": dict(zip(mech.output_names, map(float, outputs))),
        }
    return {"collision": entry}


def run_evaluate(args) -> int:
    mech = load(args.file)
    design = design_arg(mech, args.design)
    payload = evaluation_payload(mech, evaluate(mech, design), design)
    moves = moved_points(mech, mech.design.p0 if design is None else design)
    payload["moved_points"] = [m.as_json(mech.design.names) for m in moves]
    if args.json:
        print(json.dumps(payload, indent=2))
        return 0
    print(
        f"{mech.name}: f_design = {payload['f_design']:.4g} (reach "
        f"{payload['reach']:.4g}, singularity {payload['singularity']:.4g}"
        + (
            f", collision {payload['collision']['share']:.4g}"
            if "collision" in payload
            else ""
        )
        + "); "
        f"regulariser {payload['regularizer']:.4g}; α₋ = {payload['alpha_minus']:.4g}"
    )
    rest = payload["rest_pose"]
    source = (
        "set in the file"
        if mech.evaluation.alpha_minus is not None
        else (f"{mech.evaluation.alpha_factor:g} x the rest pose's f_sing")
    )
    print(
        f"  α₋ {source}; initial design's rest pose: σ_min FK "
        f"{rest['sigma_min_fk']:.4g}, BK {rest['sigma_min_bk']:.4g} (homogenised), "
        f"f_sing {rest['f_sing']:.4g}; ∂b/∂a σ_min {rest['jacobian_sigma_min']:.4g}, "
        f"σ_max {rest['jacobian_sigma_max']:.4g} (file units)"
    )
    print(
        f"  {'target':<22} {'IK reached':<22} {'f_BK':>9} {'f_sing IK':>10} "
        f"{'f_sing adv':>10} {'culled':>9}"
    )
    for sample in payload["samples"]:
        target = ", ".join(f"{v:.4g}" for v in sample["target"].values())
        reached = ", ".join(f"{v:.4g}" for v in sample["ik"]["reached"].values())
        print(
            f"  {target:<22} {reached:<22} {sample['ik']['f_bk']:9.2e} "
            f"{sample['ik']['f_sing']:10.4g} {sample['adversarial']['f_sing']:10.4g} "
            f"{sample['adversarial']['culled']:9.3g}"
        )
    caps = payload["capped_samples"]
    if caps["ik"] or caps["adversarial"]:
        settings = mech.evaluation
        print(
            f"  {caps['ik']} IK and {caps['adversarial']} adversarial minimisations "
            f"ran to their caps ({settings.ik_iterations} and "
            f"{settings.adversarial_iterations} iterations): their f_design share may "
            "read low; `linkopt verify` checks the whole range"
        )
    if "collision" in payload:
        _print_collision(payload["collision"])
    from .payloads import held_line

    if line := held_line(payload.get("motor_limits", {})):
        print(line)
    from .._design.on_bounds import bounds_line

    line = bounds_line(payload["at_bounds"])
    if line is not None:
        print(f"  {line}")
    print_moves(mech, moves, "at this design")
    return 0


def _print_collision(entry: dict) -> None:
    """``evaluate``'s lines on the collision term and the closest pair."""
    print(
        f"  collision term {entry['term']:.4g} (weight {entry['weight']:g}: "
        f"{entry['share']:.4g} of f_design; "
        f"clearance {entry['clearance']:.4g}); least clearance "
        f"{entry['min_clearance']:.4g}"
        + ("" if entry["pair"] is None else " between " + " and ".join(entry["pair"]))
    )
    pose = entry["pose"]
    if pose is not None:
        outputs = ", ".join(f"{n}={v:.4g}" for n, v in pose["outputs"].items())
        motors = ", ".join(f"{n}={v:.4g}" for n, v in pose["motors"].items())
        print(
            f"    at the {pose['sample']} sample of target {pose['target']}: "
            f"{outputs} (motors {motors})"
        )


def run_plot(args) -> int:
    if args.resolution is not None and args.resolution < 8:
        raise InputError(
            f"--resolution: expected at least 8 cells per axis, got {args.resolution}"
        )
    label = _label(args.label, args.design)
    mech = load(args.file)
    from .._design.maps import check_count, check_plot_resolution
    from .._draw.plots import plot_mechanism

    design = design_arg(mech, args.design)
    max_cells = check_count(args.max_cells, "--max-cells", 1)
    spaces = mech.num_motors == mech.num_outputs and mech.num_motors in (2, 3)
    resolution = args.resolution
    if spaces:  # the maps' cost, before any solve
        resolution = check_plot_resolution(
            mech,
            args.resolution,
            where="--resolution",
            max_cells=max_cells,
            raise_with="--max-cells",
        )
    out = output_folder(args.out, "--out")  # before any solve: a bad --out is exit 2
    stem = Path(args.file).stem
    if spaces:
        path = out / f"{stem}_{label}.png"
        _plot_spaces(mech, design, resolution, max_cells, path, not args.no_clearance)
    else:
        print(
            f"{args.file}: space plots need 2 or 3 motors and outputs, the file has "
            f"{mech.num_motors}; drawing the mechanism only",
            file=sys.stderr,
        )
    print(
        plot_mechanism(
            mech, out / f"{stem}_{label}_mechanism.png", designs={label: design}
        )
    )
    return 0


def _label(label: str | None, design: str | None) -> str:
    """``--label``, a plain file-name part (default 'initial', or 'design' with
    ``--design``)."""
    if label is None:
        return "initial" if design is None else "design"
    if not label or label in (".", "..") or any(c in label for c in "/\\\0"):
        raise InputError(
            f"--label: expected a file-name part without '/', got {label!r}"
        )
    return label


def _plot_spaces(
    mech, design, resolution: int, max_cells: int, path: Path, clearance: bool
) -> None:
    """Evaluate the design and draw its motor- and end-effector-space maps (and their
    clearance, with ``clearance`` and ``[collision]`` enabled)."""
    from .._draw.space_plots import plot_spaces

    print(f"evaluating {mech.name} ...", file=sys.stderr)
    ev = evaluate(mech, design)
    grids = "grids" if mech.num_motors == 2 else "grids (three 2-D sections each)"
    print(
        f"solving the {resolution}x{resolution} motor and end-effector {grids} ...",
        file=sys.stderr,
    )
    print(
        plot_spaces(
            mech,
            ev,
            path,
            resolution=resolution,
            design=design,
            max_cells=max_cells,
            progress=map_progress(),
            clearance=clearance,
        )
    )


def register(subparsers) -> None:
    """Add ``evaluate`` and ``plot`` to the ``linkopt`` sub-commands."""
    evaluate_cmd = subparsers.add_parser(
        "evaluate", help="IK and adversarial samples, f_design (paper Sec. IV)"
    )
    evaluate_cmd.add_argument("file")
    evaluate_cmd.add_argument("--design", help=_DESIGN_HELP)
    evaluate_cmd.add_argument(
        "--json", action="store_true", help="machine-readable output"
    )
    evaluate_cmd.set_defaults(run=run_evaluate)
    _register_plot(subparsers)


def _register_plot(subparsers) -> None:
    plot = subparsers.add_parser(
        "plot", help="motor- and end-effector-space maps and a drawing (PNG)"
    )
    plot.add_argument("file")
    plot.add_argument("--design", help="as for evaluate")
    plot.add_argument("--out", required=True, help="output directory")
    plot.add_argument(
        "--resolution",
        type=int,
        help=(
            "grid cells per axis of each map (default 60 for two outputs, 40 for the "
            "2-D sections of three)"
        ),
    )
    plot.add_argument(
        "--label", help="file-name label (default 'initial', or 'design' with --design)"
    )
    add_max_cells(plot)
    plot.add_argument(
        "--no-clearance",
        action="store_true",
        help=(
            "with [collision] enabled, leave out the maps of the least clearance "
            "between links drawn below the f_sing maps"
        ),
    )
    plot.set_defaults(run=run_plot)
