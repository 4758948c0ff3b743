"""Linkage synthesis: a design whose whole cycle traces a path, drives a
function or guides a body through target poses, free of forward singularities.

Each name is also a top-level name of :mod:`linkopt`, the same object: ``synthesize``
is ``linkopt.synthesize``, ``Targets`` ``linkopt.SynthesisTargets``, ``load_targets``
``linkopt.load_synthesis_targets``, ``SynthesisResult`` ``linkopt.SynthesisResult``,
``score`` ``linkopt.score_synthesis`` and ``verify`` ``linkopt.verify_synthesis``.
"""

from typing import TYPE_CHECKING

from ._namespace import namespace as _namespace

#: each name here -> its top-level name in :mod:`linkopt`
_TOP_LEVEL = {
    "Targets": "SynthesisTargets",
    "load_targets": "load_synthesis_targets",
    "SynthesisResult": "SynthesisResult",
    "synthesize": "synthesize",
    "score": "score_synthesis",
    "verify": "verify_synthesis",
}

__getattr__, __dir__ = _namespace(__name__, _TOP_LEVEL)

if TYPE_CHECKING:  # the eager imports, for type checkers and editors
    from ._synth.run import SynthesisResult, synthesize, verify
    from ._synth.run import score_design as score
    from ._synth.targets import Targets, load_targets

__all__ = sorted(_TOP_LEVEL)
