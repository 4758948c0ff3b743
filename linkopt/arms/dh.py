"""DH tables synthesised for manipulability (Sobh & Toundykov, paper 004): a serial
arm's Denavit–Hartenberg table chosen so that its tip reaches given points far from
singular configurations, and the table as a linkopt :class:`~linkopt.Mechanism`.

This namespace is the only home of its names. Until the next release the old
top-level names still work, with a ``DeprecationWarning`` naming the name here
(``linkopt.DHTable``, ``linkopt.dh_mechanism``, ...).
"""

from typing import TYPE_CHECKING

from .._namespace import namespace as _namespace

#: each name here -> (its module under :mod:`linkopt`, its name there)
_NAMES = {
    "DHTable": ("_arms.dh.table", "DHTable"),
    "to_mechanism": ("_arms.dh.table", "to_mechanism"),
    "DHSynthesis": ("_arms.dh.synthesis", "DHSynthesis"),
    "DHSynthesisSettings": ("_arms.dh.settings", "DHSynthesisSettings"),
    "synthesize": ("_arms.dh.synthesis", "synthesize_dh"),
}

__getattr__, __dir__ = _namespace(__name__, _NAMES)

if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from .._arms.dh.settings import DHSynthesisSettings
    from .._arms.dh.synthesis import DHSynthesis
    from .._arms.dh.synthesis import synthesize_dh as synthesize
    from .._arms.dh.table import DHTable, to_mechanism

__all__ = sorted(_NAMES)
