"""Serial arms on linkopt's engine, one namespace per family: :mod:`.codesign`
(design and trajectory of an arm, paper 000), :mod:`.dh` (DH synthesis for
manipulability, paper 004) and :mod:`.trace` (planar arms tracing paths, paper 002).

Each name of a family is also a top-level name of :mod:`linkopt`, the same object
(``linkopt.arms.dh.synthesize`` is ``linkopt.synthesize_dh``); the namespaces import
nothing until a name is used.
"""

from .._namespace import namespace as _namespace

__all__ = ["codesign", "dh", "trace"]

__getattr__, __dir__ = _namespace(__name__, {}, __all__)
