"""Results of continuous-path synthesis as JSON and as a linkopt mechanism file.

The arm becomes a planar serial chain (:mod:`linkopt._arms.chain`) of revolute joints
about z whose rest pose is the state at the task's first point ``S_{1,i}`` (linkopt
bodies sit at identity orientation at rest, and motor values are measured from it).
Outputs: the tip's x and y. The loader asks for as many outputs as motors (the
mobility), so a 3-link arm gets a third output, the angle of its shoulder joint, i.e.
the static proximal link's angle (relative to the rest pose, as motors are) — exactly
the variable the synthesis fixes per primitive. :func:`engine_state` is that
mechanism's state of any arm configuration in closed form.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..._engine import rotations as rot
from ..._engine.model import Mechanism
from ..._files.writer import dumps
from ..chain import chain_definition, chain_state, coordinate_output, joint_output
from . import geometry as geo
from .synthesis import TraceResult
from .task import TraceTask
from .verify import PlanarArm, critical_states

CRITICAL = ("initial", "final", "closest", "farthest")
JOINTS = ("shoulder", "elbow", "wrist")
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
        "attempts": list(result.attempts),
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
        "failures": list(v.failures),
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


def rest_pose(result: TraceResult) -> Float[np.ndarray, "n+1 2"]:
    """Joint positions ``s_1 .. s_{n+1}`` of the exported arm's rest pose: the state at
    the task's first point."""
    return critical_states(result.task, result.design)[0][0]


def _outputs(task: TraceTask, design: PlanarArm, rest: np.ndarray) -> list[dict]:
    """The tip's x and y over the task's bounding box (plus a margin) and, for 3 links,
    the shoulder's angle from rest over the static proximal angles."""
    pts = np.concatenate(
        [np.asarray(geo.points(p, np.linspace(0.0, 1.0, 65))) for p in task.primitives]
    )
    pad = 0.05 * task.scale
    outputs = [
        coordinate_output(
            c, "tip", c, float(pts[:, i].min() - pad), float(pts[:, i].max() + pad)
        )
        for i, c in enumerate("xy")
    ]
    if design.n_links == 3:
        rel = design.proximal_angles - np.arctan2(*(rest[1] - rest[0])[::-1])
        outputs.append(
            joint_output(
                "shoulder_angle",
                "shoulder",
                float(rel.min() - 0.1),
                float(rel.max() + 0.1),
            )
        )
    return outputs


def mechanism_definition(result: TraceResult) -> dict:
    """The arm as a parsed mechanism definition (see module docstring)."""
    task, d = result.task, result.design
    rest = rest_pose(result)
    n = d.n_links
    spatial = np.column_stack([rest, np.zeros(len(rest))])
    return chain_definition(
        f"{task.name} arm",
        ["ground"] + [f"link{k + 1}" for k in range(n)],
        list(JOINTS[:n]),
        [f"theta{k + 1}" for k in range(n)],
        spatial[:-1],
        np.tile([0.0, 0.0, 1.0], (n, 1)),
        points=[("tip", n, spatial[-1])],
        outputs=_outputs(task, d, rest),
        # no `units`: a trace task does not name its length unit (the header says the
        # lengths are the task's), and `linkopt export` reads a file without one as
        # metres and says so; "task units" made every export of the file fail
    )


def _body_frames(
    states: Float[Array, "n+1 2"],
) -> tuple[Float[Array, "n+1 4"], Float[Array, "n+1 3"]]:
    """Orientation and position of the frame each body carries: the world frame for the
    ground, for link ``k`` its direction about z at its proximal joint."""
    links = states[1:] - states[:-1]
    angles = jnp.arctan2(links[:, 1], links[:, 0])
    rotations = rot.from_axis_angle(jnp.array([0.0, 0.0, 1.0]), angles)
    identity = jnp.array([[1.0, 0.0, 0.0, 0.0]])
    positions = jnp.concatenate([states[:-1], jnp.zeros((len(links), 1))], axis=1)
    return (
        jnp.concatenate([identity, rotations]),
        jnp.concatenate([jnp.zeros((1, 3)), positions]),
    )


def engine_state(
    mech: Mechanism, rest: Float[Array, "n+1 2"], states: Float[Array, "n+1 2"]
) -> Float[Array, " S"]:
    """The homogenised state of the exported mechanism ``mech`` (:func:`mechanism_text`)
    with the arm's joints at ``states`` ``(s_1 .. s_{n+1})``; ``rest`` is its
    :func:`rest_pose` (:func:`linkopt._arms.chain.chain_state`)."""
    rotations, positions = _body_frames(jnp.asarray(states))
    rest_rotations, rest_positions = _body_frames(jnp.asarray(rest))
    offsets = jnp.asarray(mech.body_origins) - rest_positions
    return chain_state(rotations, positions, rest_rotations, mech.length_scale, offsets)


def mechanism_text(result: TraceResult) -> str:
    d = result.design
    lengths = ", ".join(f"{r:.6g}" for r in d.lengths)
    head = (
        f"# Planar {d.n_links}-link arm synthesised by `linkopt arm trace` for task "
        f"{result.task.name!r}\n"
        f"# ({result.task.source}); rest pose = the state at the task's first point. "
        "Link lengths\n"
        f"# {lengths}; elbow {'up' if d.sigma > 0 else 'down'}. Lengths are in the "
        "task's unit (no `units`:\n# `linkopt export` takes metres).\n\n"
    )
    return head + dumps(mechanism_definition(result))
