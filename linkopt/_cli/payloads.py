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
            for n, j, lin in zip(mech.motor_names, mech.motor_joints, mech.motor_linear)
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
