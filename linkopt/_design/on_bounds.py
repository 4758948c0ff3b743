"""Which design parameters sit on a bound (five of six parameters of an
optimised design ended on their bounds, and nothing said so).

A parameter is on a bound when it lies within ``BOUND_TOLERANCE`` of its range
(``upper - lower``) from it: the optimiser's moves are clipped onto the bounds
(pyswarms' ``nearest`` handler, and the gradient step's clip), so a parameter that the
optimiser pushed against a bound sits on it exactly, and 1e-6 of the range leaves room
for a design read back from a file. A parameter on a bound means the optimum may lie
beyond it: a wider range, or another parameter, may do better.
"""

from __future__ import annotations

import numpy as np
from jaxtyping import Float

from .._engine.model import Mechanism

#: Distance from a bound, as a share of the parameter's range, within which a
#: parameter counts as on it.
BOUND_TOLERANCE = 1e-6


def on_bounds(
    mech: Mechanism, design: Float[np.ndarray, " n_p"] | None = None
) -> dict[str, dict]:
    """``{name: {"bound": "lower" | "upper", "value": v, "limit": bound}}`` for each
    parameter of ``design`` (file units; None: the file's) on a bound, in parameter
    order."""
    d = mech.design
    values = np.asarray(d.p0 if design is None else design, dtype=float)
    band = BOUND_TOLERANCE * (d.upper - d.lower)
    found = {}
    for k, name in enumerate(d.names):
        for side, limit in (("lower", d.lower[k]), ("upper", d.upper[k])):
            if abs(values[k] - limit) <= band[k]:
                found[name] = {
                    "bound": side,
                    "value": float(values[k]),
                    "limit": float(limit),
                }
                break
    return found


def bounds_line(found: dict[str, dict]) -> str | None:
    """One line naming the parameters on a bound, or None when none is."""
    if not found:
        return None
    names = ", ".join(
        f"{name} = {entry['value']:g} ({entry['bound']} bound)"
        for name, entry in found.items()
    )
    return (
        f"{len(found)} parameter(s) on a bound (within {BOUND_TOLERANCE:g} of its "
        f"range): {names}; the optimum may lie beyond it"
    )
