"""Serial arms on linkopt's engine, one namespace per family: :mod:`.codesign`
(design and trajectory of an arm, paper 000), :mod:`.dh` (DH synthesis for
manipulability, paper 004) and :mod:`.trace` (planar arms tracing paths, paper 002).

The namespaces are the only home of their names (``linkopt.arms.dh.synthesize``; the
old top-level ``linkopt.synthesize_dh`` warns until the next release) and import
nothing until a name is used.
"""

from .._namespace import namespace as _namespace

__all__ = ["codesign", "dh", "trace"]

__getattr__, __dir__ = _namespace(__name__, {}, __all__)
