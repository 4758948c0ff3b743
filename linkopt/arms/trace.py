"""Planar arms that trace continuous paths around obstacles (Campos et al., paper
002): a task file, the synthesis of an arm whose tip follows the path with its links
clear of the obstacles, its verification, and the comparison with the discretised
approach (a design that only reaches points of the path).

Each name is also a top-level name of :mod:`linkopt`, the same object: functions lose
the ``trace`` the namespace says (``synthesize`` is ``linkopt.synthesize_trace``,
``verify`` is ``linkopt.verify_trace``), classes keep their names.
"""

from typing import TYPE_CHECKING

from .._namespace import namespace as _namespace

#: each name here -> its top-level name in :mod:`linkopt`
_TOP_LEVEL = {
    "TraceTask": "TraceTask",
    "load_task": "load_trace_task",
    "loads_task": "loads_trace_task",
    "TraceSettings": "TraceSettings",
    "TraceResult": "TraceResult",
    "synthesize": "synthesize_trace",
    "PlanarArm": "PlanarArm",
    "TraceVerification": "TraceVerification",
    "verify": "verify_trace",
    "DiscreteComparison": "DiscreteComparison",
    "compare_discretised": "compare_discretised",
    "discretised_design": "discretised_design",
}

__getattr__, __dir__ = _namespace(__name__, _TOP_LEVEL)

if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from .._arms.trace.discrete import DiscreteComparison, discretised_design
    from .._arms.trace.discrete import compare as compare_discretised
    from .._arms.trace.settings import TraceSettings
    from .._arms.trace.synthesis import TraceResult, synthesize
    from .._arms.trace.task import TraceTask, load_task, loads_task
    from .._arms.trace.verify import PlanarArm, TraceVerification, verify

__all__ = sorted(_TOP_LEVEL)
