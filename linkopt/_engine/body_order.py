"""The order of a mechanism's bodies in the block-band storage of
:mod:`linkopt._engine.banded`: a narrow band, and where a few bodies are joined to
many others (a walker's ground and crank, which every leg hangs from) those *hubs*
last, an arrowhead.

A constraint row touches at most two bodies, so ``JᵀJ`` has a ``7 x 7`` block for
each pair of bodies that share a row. Numbered in a reverse Cuthill–McKee order, the
pairs lie within ``w`` places of each other (the band). A hub joined to every leg
widens that band to the whole mechanism; numbered last instead, its blocks fill ``h``
block rows at the bottom (the border) and the rest of the bodies, the legs, fall into
separate components of a narrow band. :func:`body_order` picks the number of hubs
(none, or the ``1 .. MAX_HUBS`` bodies of most neighbours, each joined to at least
:data:`HUB_DEGREE` others) that makes the factor cheapest by :func:`cost`.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np

#: Fewest distinct neighbours of a hub candidate. A ladder's rungs have 6 and a lazy
#: tongs' links 4, and they stay in the band; a walker's ground and crank have two per
#: leg (a strandbeest of 4 legs: 9).
HUB_DEGREE = 8
#: Most hubs numbered last (the corner block is a dense ``7h x 7h`` factor).
MAX_HUBS = 8


@dataclass(frozen=True)
class Layout:
    """Where each body sits: ``position[b]`` its block row, ``order`` the inverse
    (``order[position[b]] = b``), ``width`` the band's ``w`` (at least 1) over the
    first ``B - hubs`` rows, ``hubs`` the bodies numbered last (0: a plain band)."""

    order: np.ndarray
    position: np.ndarray
    width: int
    hubs: int = 0


def _peripheral_order(graph, num_bodies: int) -> np.ndarray:
    """Breadth-first order from a pseudo-peripheral body of each component (two
    sweeps: the last body reached from the first, then from that one), reversed:
    Cuthill–McKee's level structure from a far end."""
    from scipy.sparse.csgraph import breadth_first_order

    seen = np.zeros(num_bodies, dtype=bool)
    parts = []
    for root in range(num_bodies):
        if seen[root]:
            continue
        far = breadth_first_order(graph, root, directed=False)[0][-1]
        far = breadth_first_order(graph, far, directed=False)[0][-1]
        order = breadth_first_order(graph, far, directed=False)[0]
        seen[order] = True
        parts.append(order)
    return np.concatenate(parts)[::-1]


def _width(edges: np.ndarray, order: np.ndarray) -> int:
    position = np.empty(order.size, dtype=np.int64)
    position[order] = np.arange(order.size)
    spread = np.abs(position[edges[:, 0]] - position[edges[:, 1]])
    return int(np.max(spread, initial=0))


def _graph(edges: np.ndarray, num_bodies: int):
    """The bodies' adjacency (CSR). scipy.sparse is imported here, not with the
    module: only files that take the band need it, and its import was 0.1-0.2 s of
    every command's start (and of each worker's)."""
    import scipy.sparse

    graph = scipy.sparse.coo_matrix(
        (np.ones(len(edges)), (edges[:, 0], edges[:, 1])), (num_bodies,) * 2
    ).tocsr()
    return graph + graph.T


def _band_order(num_bodies: int, edges: np.ndarray) -> tuple[np.ndarray, int]:
    """The narrowest band of three orders: the file's, scipy's reverse Cuthill–McKee
    (which starts from a body of least degree, in the middle of a long ladder) and
    reverse Cuthill–McKee levels from a pseudo-peripheral body; and its width."""
    from scipy.sparse.csgraph import reverse_cuthill_mckee

    graph = _graph(edges, num_bodies)
    candidates = [
        np.arange(num_bodies),
        np.asarray(reverse_cuthill_mckee(graph, symmetric_mode=True)),
        _peripheral_order(graph, num_bodies),
    ]
    order = min(candidates, key=lambda o: _width(edges, o))
    return order, _width(edges, order)


def cost(rows: int, width: int, hubs: int) -> int:
    """The factor's work in ``7 x 7`` block products: the band's ``rows (w + 1)²``,
    the border's forward substitution and Schur update ``rows h (w + 1 + h)``, the
    corner's ``h³``."""
    w1 = width + 1
    return rows * w1 * w1 + rows * hubs * (w1 + hubs) + hubs**3


def _hub_candidates(edges: np.ndarray, num_bodies: int) -> np.ndarray:
    graph = _graph(edges, num_bodies)
    degree = np.diff((graph > 0).tocsr().indptr)
    ranked = np.argsort(-degree, kind="stable")
    return ranked[degree[ranked] >= HUB_DEGREE][: min(MAX_HUBS, num_bodies - 1)]


def _with_hubs(num_bodies: int, edges: np.ndarray, hubs: np.ndarray):
    """``(order, width)``: the bodies but ``hubs`` in their narrowest band, then
    ``hubs``."""
    rest = np.setdiff1d(np.arange(num_bodies), hubs)
    label = np.full(num_bodies, -1, dtype=np.int64)
    label[rest] = np.arange(rest.size)
    inner = edges[np.all(label[edges] >= 0, axis=1)]
    order, width = _band_order(rest.size, label[inner])
    return np.concatenate([rest[order], hubs]).astype(np.int64), width


@functools.lru_cache(maxsize=64)
def _layout(num_bodies: int, pairs: bytes) -> Layout:
    edges = np.frombuffer(pairs, dtype=np.int64).reshape(-1, 2)
    edges = edges[edges[:, 0] != edges[:, 1]]
    order, width = _band_order(num_bodies, edges)
    hubs, best = 0, cost(num_bodies, max(width, 1), 0)
    candidates = _hub_candidates(edges, num_bodies)
    for h in range(1, candidates.size + 1):
        trial, trial_width = _with_hubs(num_bodies, edges, candidates[:h])
        trial_cost = cost(num_bodies - h, max(trial_width, 1), h)
        if trial_cost < best:
            order, width, hubs, best = trial, trial_width, h, trial_cost
    position = np.empty(num_bodies, dtype=np.int64)
    position[order] = np.arange(num_bodies)
    return Layout(order, position, max(width, 1), hubs)


def body_order(num_bodies: int, pairs: np.ndarray) -> Layout:
    """The :class:`Layout` of bodies coupled by ``pairs`` ``(E, 2)`` (body indices;
    isolated bodies keep a place of their own)."""
    pairs = np.ascontiguousarray(np.asarray(pairs, dtype=np.int64).reshape(-1, 2))
    return _layout(num_bodies, pairs.tobytes())
