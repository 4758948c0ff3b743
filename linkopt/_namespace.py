"""The ``__getattr__`` and ``__dir__`` of linkopt's public namespaces
(:mod:`linkopt.arms.codesign`, :mod:`linkopt.arms.dh`, :mod:`linkopt.arms.trace`,
:mod:`linkopt.export`, :mod:`linkopt.synthesis`): a name is imported on first use, so
listing a namespace imports no JAX.
"""

from __future__ import annotations

import importlib
import sys
from collections.abc import Callable, Iterable, Mapping

PACKAGE = __name__.rpartition(".")[0]


def namespace(
    module: str,
    names: Mapping[str, tuple[str, str]],
    submodules: Iterable[str] = (),
) -> tuple[Callable[[str], object], Callable[[], list[str]]]:
    """The ``__getattr__`` and ``__dir__`` (PEP 562) of the public namespace
    ``module``: its name ``name`` is ``names[name] = (private module, attribute)``
    under :mod:`linkopt`, imported on first use after :mod:`linkopt._config` (float64
    on, as for the top-level names); each of ``submodules`` is imported on first
    use."""
    submodules = tuple(submodules)

    def __getattr__(name: str):
        if name in submodules:
            value = importlib.import_module(f"{module}.{name}")
        elif name in names:
            importlib.import_module(f"{PACKAGE}._config")
            source, attribute = names[name]
            value = getattr(importlib.import_module(f"{PACKAGE}.{source}"), attribute)
        else:
            raise AttributeError(f"module {module!r} has no attribute {name!r}")
        setattr(sys.modules[module], name, value)
        return value

    def __dir__() -> list[str]:
        return sorted(set(vars(sys.modules[module])) | set(names) | set(submodules))

    return __getattr__, __dir__
