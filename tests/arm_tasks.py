"""The tiny 2-joint arm shared by the arm tests: a base that slides in z, a joint, a
link of free length, a second joint and a tool; and the targets it reaches for a known
design."""

import jax.numpy as jnp
import numpy as np

from linkopt._arms.codesign.model import chain
from linkopt._arms.codesign.task import loads_task
from linkopt._engine.rotations import matrix

TINY_ARM = """
[task]
name = "tiny"
gravity = [0.0, 0.0, -9.81]
torque_limit = 9.0
module_radius = 0.03
[[modules]]
type = "base"
z = { min = 0.0, max = 0.2 }
[[modules]]
type = "joint"
mass = 0.3
[[modules]]
type = "link"
length = { min = 0.1, max = 0.5 }
twist = 1.5707963267948966
mass = 0.2
[[modules]]
type = "joint"
mass = 0.3
[[modules]]
type = "tool"
length = 0.2
mass = 0.1
"""


def reached_targets(text: str, design, poses, *, axis: bool = False) -> str:
    """``[[targets]]`` tables at the tool of ``text``'s arm for ``design`` at joint
    ``poses`` (with the tool's z axis as tip axis when ``axis``)."""
    skeleton = loads_task(
        text + "[[targets]]\nposition = [0.0, 0.0, 0.0]\n", "skeleton.toml"
    )
    tables = ""
    for theta in poses:
        ends, _ = chain(
            skeleton.arm.modules,
            jnp.asarray(theta, dtype=float),
            jnp.asarray(design, dtype=float),
        )
        q, p = ends[-1]
        tables += f"[[targets]]\nposition = {[float(v) for v in p]}\n"
        if axis:
            tables += f"axis = {[float(v) for v in np.asarray(matrix(q))[:, 2]]}\n"
    return tables
