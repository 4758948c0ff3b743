"""Results of continuous-path synthesis as JSON and as a linkopt mechanism file.

The arm becomes a planar serial chain of revolute joints about z whose rest pose is the
state at the task's first point ``S_{1,i}`` (linkopt bodies sit at identity orientation
at rest, and motor values are measured from it). Outputs: the tip's x and y. The loader
asks for as many outputs as motors (the mobility), so a 3-link arm gets a third output,
the angle of its shoulder joint, i.e. the static proximal link's angle (relative to the
rest pose, as motors are) — exactly the variable the synthesis fixes per primitive.
"""

from __future__ import annotations

import numpy as np

from ..._engine.writer import dumps
from . import geometry as geo
from .synthesis import TraceResult
from .verify import PlanarArm, critical_states

CRITICAL = ("initial", "final", "closest", "farthest")
CONTROL_ROWS = 100


def _rows(a: np.ndarray, k: int = CONTROL_ROWS) -> np.ndarray:
    """At most ``k`` evenly spread rows of ``a`` (first and last kept)."""
    idx = np.unique(np.linspace(0, len(a) - 1, min(k, len(a))).round().astype(int))
    return a[idx]


def result_dict(result: TraceResult) -> dict:
    """JSON-ready summary: design, per-primitive critical states and joint-angle
    trajectories (≤ 100 rows each), verification figures and every NLP attempt."""
    task = result.task
    out = {
        "task": task.name,
        "source": task.source,
        "success": result.success,
        "seconds": result.seconds,
        "attempts": result.attempts,
    }
    if not result.success:
        return out
    d, v = result.design, result.verification
    out.update(design_dict(d), swept_bound=result.swept)
    crit = critical_states(task, d)
    out["primitives"] = [
        {
            "index": j,
            "type": p.kind,
            "critical_states": {
                name: {
                    "joints": crit[j][k].tolist(),
                    "joint_angles": np.asarray(geo.joint_angles(crit[j][k][None]))[
                        0
                    ].tolist(),
                }
                for k, name in enumerate(CRITICAL)
                if p.kind != "circle" or k >= 2 or k == 0
            },
        }
        for j, p in enumerate(task.primitives)
    ]
    out["control"] = [
        {"kind": s.kind, "index": s.index, "joint_angles": _rows(s.angles).tolist()}
        for s in v.segments
    ]
    out["verification"] = {
        "passed": v.passed,
        "failures": v.failures,
        "min_clearance": v.min_clearance,
        "min_self_distance": v.min_self_distance,
        "min_reach_margin": v.min_reach_margin,
        "max_joint_step": v.max_joint_step,
        "samples": int(sum(len(s.states) for s in v.segments)),
    }
    return out


def design_dict(d: PlanarArm) -> dict:
    return {
        "n_links": d.n_links,
        "base": d.base.tolist(),
        "link_lengths": d.lengths.tolist(),
        "total_length": float(d.lengths.sum()),
        "elbow": "up" if d.sigma > 0 else "down",
        "proximal_angles": d.proximal_angles.tolist(),
    }


def mechanism_definition(result: TraceResult) -> dict:
    """The arm as a parsed mechanism definition (see module docstring)."""
    task, d = result.task, result.design
    rest = critical_states(task, d)[0][0]
    n = d.n_links
    names = ["shoulder", "elbow", "wrist"][:n] if n == 3 else ["shoulder", "elbow"]
    bodies = ["ground"] + [f"link{k + 1}" for k in range(n)]
    z3 = lambda p: [float(p[0]), float(p[1]), 0.0]
    joints = [
        {
            "name": names[k],
            "type": "revolute",
            "bodies": [bodies[k], bodies[k + 1]],
            "anchor": z3(rest[k]),
            "axis": [0.0, 0.0, 1.0],
        }
        for k in range(n)
    ]
    pts = np.concatenate(
        [np.asarray(geo.points(p, np.linspace(0.0, 1.0, 65))) for p in task.primitives]
    )
    pad = 0.05 * task.scale
    outputs = [
        {
            "name": c,
            "point": "tip",
            "coordinate": c,
            "min": float(pts[:, i].min() - pad),
            "max": float(pts[:, i].max() + pad),
        }
        for i, c in enumerate("xy")
    ]
    if n == 3:
        rel = d.proximal_angles - np.arctan2(*(rest[1] - rest[0])[::-1])
        outputs.append(
            {
                "name": "shoulder_angle",
                "joint": "shoulder",
                "min": float(rel.min() - 0.1),
                "max": float(rel.max() + 0.1),
            }
        )
    return {
        "mechanism": {
            "name": f"{task.name} arm",
            "ground": "ground",
            "units": "task units",
        },
        "bodies": [{"name": b} for b in bodies],
        "joints": joints,
        "motors": [{"name": f"theta{k + 1}", "joint": names[k]} for k in range(n)],
        "points": [{"name": "tip", "body": bodies[-1], "position": z3(rest[-1])}],
        "outputs": outputs,
    }


def mechanism_text(result: TraceResult) -> str:
    d = result.design
    head = (
        f"# Planar {d.n_links}-link arm synthesised by `linkopt arm trace` for task {result.task.name!r}\n"
        f"# ({result.task.source}); rest pose = the state at the task's first point. Link lengths\n"
        f"# {', '.join(f'{r:.6g}' for r in d.lengths)}; elbow {'up' if d.sigma > 0 else 'down'}.\n\n"
    )
    return head + dumps(mechanism_definition(result))
