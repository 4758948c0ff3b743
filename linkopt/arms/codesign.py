"""Co-design of a serial arm and its trajectory (Whitman & Choset, paper 000): a task
file, the arm's modules, the nonlinear program that chooses the arm's design and the
joint angles of its waypoints together (around obstacles, within torque limits), and
the elimination of the joints a task does not need.

This namespace is the only home of its names. Until the next release the old
top-level names still work, with a ``DeprecationWarning`` naming the name here
(``linkopt.ArmTask``, ``linkopt.load_arm_task``, ...).
"""

from typing import TYPE_CHECKING

from .._namespace import namespace as _namespace

#: each name here -> (its module under :mod:`linkopt`, its name there)
_NAMES = {
    "ArmTask": ("_arms.codesign.task", "Task"),
    "load_task": ("_arms.codesign.task", "load_task"),
    "loads_task": ("_arms.codesign.task", "loads_task"),
    "Arm": ("_arms.codesign.model", "Arm"),
    "ArmSolution": ("_arms.codesign.multistart", "ArmSolution"),
    "prepare": ("_arms.codesign.nlp", "prepare"),
    "solve": ("_arms.codesign.multistart", "solve"),
    "eliminate": ("_arms.codesign.elimination", "eliminate"),
    "simplify": ("_arms.codesign.elimination", "simplify"),
}

__getattr__, __dir__ = _namespace(__name__, _NAMES)

if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from .._arms.codesign.elimination import eliminate, simplify
    from .._arms.codesign.model import Arm
    from .._arms.codesign.multistart import ArmSolution, solve
    from .._arms.codesign.nlp import prepare
    from .._arms.codesign.task import Task as ArmTask
    from .._arms.codesign.task import load_task, loads_task

__all__ = sorted(_NAMES)
