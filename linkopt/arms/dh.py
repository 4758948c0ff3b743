"""DH tables synthesised for manipulability (Sobh & Toundykov, paper 004): a serial
arm's Denavit–Hartenberg table chosen so that its tip reaches given points far from
singular configurations, and the table as a linkopt :class:`~linkopt.Mechanism`.

Each name is also a top-level name of :mod:`linkopt`, the same object: functions lose
the ``dh`` the namespace says (``synthesize`` is ``linkopt.synthesize_dh``,
``to_mechanism`` is ``linkopt.dh_mechanism``), classes keep their names.
"""

from typing import TYPE_CHECKING

from .._namespace import namespace as _namespace

#: each name here -> its top-level name in :mod:`linkopt`
_TOP_LEVEL = {
    "DHTable": "DHTable",
    "to_mechanism": "dh_mechanism",
    "DHSynthesis": "DHSynthesis",
    "DHSynthesisSettings": "DHSynthesisSettings",
    "synthesize": "synthesize_dh",
}

__getattr__, __dir__ = _namespace(__name__, _TOP_LEVEL)

if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from .._arms.dh.settings import DHSynthesisSettings
    from .._arms.dh.synthesis import DHSynthesis
    from .._arms.dh.synthesis import synthesize_dh as synthesize
    from .._arms.dh.table import DHTable, to_mechanism

__all__ = sorted(_TOP_LEVEL)
