"""Linkage synthesis: a design whose whole cycle traces a path, drives a
function or guides a body through target poses, free of forward singularities.

This namespace is the only home of its names. Until the next release the old
top-level names still work, with a ``DeprecationWarning`` naming the name here
(``linkopt.SynthesisTargets``, ``linkopt.load_synthesis_targets``, ...).
"""

from typing import TYPE_CHECKING

from ._namespace import namespace as _namespace

#: each name here -> (its module under :mod:`linkopt`, its name there)
_NAMES = {
    "Targets": ("_synth.targets", "Targets"),
    "load_targets": ("_synth.targets", "load_targets"),
    "SynthesisResult": ("_synth.run", "SynthesisResult"),
    "synthesize": ("_synth.run", "synthesize"),
    "score": ("_synth.run", "score_design"),
    "verify": ("_synth.run", "verify"),
}

__getattr__, __dir__ = _namespace(__name__, _NAMES)

if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from ._synth.run import SynthesisResult, synthesize, verify
    from ._synth.run import score_design as score
    from ._synth.targets import Targets, load_targets

__all__ = sorted(_NAMES)
