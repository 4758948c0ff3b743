"""Planar arms that trace continuous paths around obstacles (Campos et al., paper
002): a task file, the synthesis of an arm whose tip follows the path with its links
clear of the obstacles, its verification, and the comparison with the discretised
approach (a design that only reaches points of the path).

This namespace is the only home of its names. Until the next release the old
top-level names still work, with a ``DeprecationWarning`` naming the name here
(``linkopt.TraceTask``, ``linkopt.load_trace_task``, ...).
"""

from typing import TYPE_CHECKING

from .._namespace import namespace as _namespace

#: each name here -> (its module under :mod:`linkopt`, its name there)
_NAMES = {
    "TraceTask": ("_arms.trace.task", "TraceTask"),
    "load_task": ("_arms.trace.task", "load_task"),
    "loads_task": ("_arms.trace.task", "loads_task"),
    "TraceSettings": ("_arms.trace.settings", "TraceSettings"),
    "TraceResult": ("_arms.trace.synthesis", "TraceResult"),
    "synthesize": ("_arms.trace.synthesis", "synthesize"),
    "PlanarArm": ("_arms.trace.verify", "PlanarArm"),
    "TraceVerification": ("_arms.trace.verify", "TraceVerification"),
    "verify": ("_arms.trace.verify", "verify"),
    "DiscreteComparison": ("_arms.trace.discrete", "DiscreteComparison"),
    "compare_discretised": ("_arms.trace.discrete", "compare"),
    "discretised_design": ("_arms.trace.discrete", "discretised_design"),
}

__getattr__, __dir__ = _namespace(__name__, _NAMES)

if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from .._arms.trace.discrete import DiscreteComparison, discretised_design
    from .._arms.trace.discrete import compare as compare_discretised
    from .._arms.trace.settings import TraceSettings
    from .._arms.trace.synthesis import TraceResult, synthesize
    from .._arms.trace.task import TraceTask, load_task, loads_task
    from .._arms.trace.verify import PlanarArm, TraceVerification, verify

__all__ = sorted(_NAMES)
