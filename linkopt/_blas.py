"""OpenBLAS held to one thread while linkopt computes.

jaxlib's LAPACK kernels call the OpenBLAS that scipy ships, which starts one thread per
core and keeps it spinning between calls. Two processes, each with that thread beside
its own, put four busy threads on two cores: the 10-design five-bar chunks then took
2.6-3.7 s per iteration instead of 1.0-1.1 s. Every chunk therefore runs with OpenBLAS
held to one thread (``threadpoolctl``): in the workers for their lifetime, in the
calling process only while it computes, so the user's own numpy keeps its threads.
One process alone gains too (20 designs: 1.9 s instead of 2.0-2.3 s).

``threadpoolctl`` only limits libraries already loaded, and jaxlib loads scipy's
OpenBLAS at its first LAPACK call, so this module imports ``scipy.linalg`` (which loads
it) before any limit is set: when nothing else had imported scipy by then, the workers'
OpenBLAS ran unlimited and five-bar iterations took 1.5 s instead of 0.77 s.
"""

from __future__ import annotations

import scipy.linalg  # noqa: F401  (loads the OpenBLAS that jaxlib calls; module docstring)
from threadpoolctl import threadpool_limits


def one_blas_thread() -> threadpool_limits:
    """OpenBLAS held to one thread, scipy's included (module docstring); also a context
    manager that restores the previous limits."""
    return threadpool_limits(1, user_api="blas")
