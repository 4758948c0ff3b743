"""Plain-data summaries of a mechanism and of solved configurations (for JSON and
text)."""

from __future__ import annotations

import numpy as np

from .._engine.constraints import constraint_rows, passive_residual
from .._engine.geometry import geometry
from .._engine.mobility import mobility
from .._engine.model import Mechanism
from .._engine.readout import (
    joint_positions,
    motor_values,
    output_values,
    point_positions,
    reported_values,
)
from .._engine.singularity import singular_values


def _named(names, rows) -> dict[str, list[float]]:
    return {name: [float(v) for v in row] for name, row in zip(names, np.asarray(rows))}


def welded_parts(mech: Mechanism) -> dict[str, str]:
    """Each body welded onto another by ``fixed`` joints, and the body it is part of
    (:mod:`linkopt._engine.welding`)."""
    if mech.welds is None:
        return {}
    names = mech.welds.parts.body_names
    return {
        names[k]: mech.body_names[b]
        for k, b in enumerate(mech.welds.body_of)
        if names[k] != mech.body_names[b]
    }


def summary(mech: Mechanism) -> dict:
    """What ``linkopt check`` reports: sizes, mobility, motors, outputs, design
    space."""
    rows = constraint_rows(mech)
    return {
        "name": mech.name,
        "file": mech.source,
        "bodies": list(mech.body_names),
        "ground": mech.body_names[mech.ground],
        "state_size": mech.state_size,
        "constraint_rows": {
            "fk": rows["fk"],
            "bk": rows["bk"],
            "passive": rows["passive"],
        },
        "mobility": mobility(mech),
        "idle_spins": [mech.body_names[b] for b in mech.idle_bodies],
        "welded": welded_parts(mech),
        "motors": {
            n: {"joint": mech.joint_names[j], "kind": "linear" if lin else "revolute"}
            | motor_limits(mech, k)
            for k, (n, j, lin) in enumerate(
                zip(mech.motor_names, mech.motor_joints, mech.motor_linear)
            )
        },
        "outputs": {
            n: {"kind": k, "min": float(lo), "max": float(hi)}
            for n, k, lo, hi in zip(
                mech.output_names, mech.output_kinds, mech.output_min, mech.output_max
            )
        },
        "reported": {
            n: {"kind": k}
            for n, k in zip(mech.reported_table.names, mech.reported_table.kinds)
        },
        "design_parameters": mech.design.size,
        "parameters": {
            n: {"initial": float(v), "min": float(lo), "max": float(hi)}
            for n, v, lo, hi in zip(
                mech.design.names, mech.design.p0, mech.design.lower, mech.design.upper
            )
        },
        "reference_length": mech.length_scale,
        "joints": {
            n: {"type": t, "anchor": [float(v) for v in a]}
            for n, t, a in zip(mech.joint_names, mech.joint_types, mech.anchors)
        },
        "collision": collision_summary(mech),
    }


def collision_summary(mech: Mechanism) -> dict | None:
    """``[collision]`` as ``check`` reports it (None without the table): whether it is
    enabled, the clearance (file units) and weight, the checked body pairs (by name),
    the capsules and capsule pairs, and the layers (distinct body layer offsets)."""
    c = mech.collision
    if c is None:
        return None
    layers = np.unique(np.round(np.asarray(c.body_offsets, dtype=float), 12), axis=0)
    return {
        "enabled": bool(c.enabled),
        "clearance": float(c.clearance),
        "weight": float(c.weight),
        "pairs": [
            [mech.body_names[a], mech.body_names[b]] for a, b in np.asarray(c.pairs)
        ],
        "capsules": len(c.segment_bodies),
        "capsule_pairs": len(c.capsule_pairs),
        "layers": len(layers),
    }


def closure(mech: Mechanism, state, design=None) -> float:
    """Largest loop-closure residual of ``state`` (homogenised): the joints'
    passive rows, quaternion norms and ground pin, without motor or output rows."""
    geom = geometry(mech, design)
    return float(np.max(np.abs(np.asarray(passive_residual(mech, geom, state)))))


def configuration(
    mech: Mechanism, state, converged: bool, residual: float, design=None
) -> dict:
    """What ``linkopt fk``/``bk`` report for one solved state."""
    sigma_fk, sigma_bk = (
        float(v) for v in np.asarray(singular_values(mech, state, design=design))
    )
    return {
        "converged": bool(converged),
        "residual": float(residual),
        "motors": dict(
            zip(
                mech.motor_names,
                map(float, np.asarray(motor_values(mech, state, design=design))),
            )
        ),
        "outputs": dict(
            zip(
                mech.output_names,
                map(float, np.asarray(output_values(mech, state, design=design))),
            )
        ),
        "reported": dict(
            zip(
                mech.reported_table.names,
                map(float, np.asarray(reported_values(mech, state, design=design))),
            )
        ),
        "joints": _named(mech.joint_names, joint_positions(mech, state, design=design)),
        "points": _named(mech.point_names, point_positions(mech, state, design=design)),
        "f_sing": 1.0 / sigma_fk + 1.0 / sigma_bk,
        "sigma_min_fk": sigma_fk,
        "sigma_min_bk": sigma_bk,
    }


def motor_limits(mech: Mechanism, motor: int) -> dict:
    """A motor's ``min`` and ``max`` (rad or file units) as ``check`` reports them:
    only the sides the file gives."""
    if not mech.motor_limited:
        return {}
    sides = {"min": mech.motor_min[motor], "max": mech.motor_max[motor]}
    return {k: float(v) for k, v in sides.items() if np.isfinite(v)}


def verified_limits(mech, result) -> dict:
    """``verify --json``'s ``motor_limits`` entry, only for a file with motor limits:
    the motor furthest beyond (or closest to) its limits, its value, its limits and
    its cell (:func:`linkopt._design.verify.limit_check`)."""
    if result.limit_excess is None:
        return {}
    entry = {"kept": not result.beyond_limits, "excess": result.limit_excess}
    if result.limit_motor is not None:
        motor = mech.motor_names.index(result.limit_motor)
        entry |= {
            "motor": result.limit_motor,
            "value": result.limit_value,
            "min": float(mech.motor_min[motor]),
            "max": float(mech.motor_max[motor]),
            "cell": dict(zip(mech.output_names, map(float, result.limit_outputs))),
        }
    return {"motor_limits": entry}


def limits_line(entry: dict) -> str:
    """One line on the motor that comes closest to, or goes furthest beyond, its
    limits (rad or file units)."""
    if "motor" not in entry:
        return "motor limits: no cell reached"
    cell = ", ".join(f"{n}={v:.4g}" for n, v in entry["cell"].items())
    span = f"[{entry['min']:.4g}, {entry['max']:.4g}]"
    if entry["kept"]:
        return (
            f"motor limits: kept; closest: motor {entry['motor']} at "
            f"{entry['value']:.4g} of {span} at {cell}"
        )
    return (
        f"motor limits: FAIL: motor {entry['motor']} needs {entry['value']:.4g}, "
        f"beyond its limits {span} by {entry['excess']:.4g}, at {cell}"
    )


def held_at_limits(mech: Mechanism, ev) -> dict:
    """``evaluate --json``'s ``motor_limits`` entry, only for a file with motor limits:
    each motor's min and max and the targets (indices into ``samples``) whose IK sample
    holds it at a limit (within 1e-9 rad or reference lengths), i.e. targets that
    need the motor beyond it when their ``f_bk`` is not zero."""
    if not mech.motor_limited:
        return {}
    motors = np.asarray(ev.ik_motors)  # homogenised
    low, high = (
        np.asarray(v) / mech.motor_scale for v in (mech.motor_min, mech.motor_max)
    )
    held = (motors <= low + 1e-9) | (motors >= high - 1e-9)
    return {
        "motor_limits": {
            name: motor_limits(mech, m) | {"held": np.flatnonzero(held[:, m]).tolist()}
            for m, name in enumerate(mech.motor_names)
        }
    }


def held_line(entry: dict) -> str | None:
    """``evaluate``'s line on the IK samples held at a motor limit (None: none)."""
    held = [
        f"{name} (targets {', '.join(map(str, motor['held']))})"
        for name, motor in entry.items()
        if motor["held"]
    ]
    return f"  IK samples held at a motor limit: {'; '.join(held)}" if held else None
