"""Co-design of a serial arm and its trajectory (Whitman & Choset, paper 000): a task
file, the arm's modules, the nonlinear program that chooses the arm's design and the
joint angles of its waypoints together (around obstacles, within torque limits), and
the elimination of the joints a task does not need.

Each name is also a top-level name of :mod:`linkopt`, the same object: functions lose
the ``arm`` the namespace says (``solve`` is ``linkopt.solve_arm``), classes keep their
names.
"""

from typing import TYPE_CHECKING

from .._namespace import namespace as _namespace

#: each name here -> its top-level name in :mod:`linkopt`
_TOP_LEVEL = {
    "ArmTask": "ArmTask",
    "load_task": "load_arm_task",
    "loads_task": "loads_arm_task",
    "Arm": "Arm",
    "ArmSolution": "ArmSolution",
    "prepare": "prepare_arm",
    "solve": "solve_arm",
    "eliminate": "eliminate",
    "simplify": "simplify",
}

__getattr__, __dir__ = _namespace(__name__, _TOP_LEVEL)

if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from .._arms.codesign.elimination import eliminate, simplify
    from .._arms.codesign.model import Arm
    from .._arms.codesign.nlp import ArmSolution, prepare, solve
    from .._arms.codesign.task import Task as ArmTask
    from .._arms.codesign.task import load_task, loads_task

__all__ = sorted(_TOP_LEVEL)
