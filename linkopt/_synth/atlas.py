"""Start four-bars for a path of many points: an atlas of coupler curves matched to
the targets' shape (numpy).

Precision-point synthesis (:func:`.fourbar.fit_path`) meets at most five points; a
curve of eight or twenty points needs four-bars whose whole coupler curve has the
targets' shape. As the atlases of the four-bar tools do (Hrones and Nelson's, and the
curve atlases behind pyslvs/four-bar), this module draws ``CURVES`` crank-rocker
four-bars in normalised form (ground ``A = 0``, ``D = 1``; the crank the shortest
link; a coupler point anywhere near the coupler; the least transmission angle over the
turn at least the one asked), samples each coupler curve at ``SAMPLES`` equal steps of
arc length, and matches it to the targets by a similarity (turn, scale, shift, and the
mirror image), in closed form for each placement of the targets along the curve:

* the targets, resampled at ``RESAMPLE`` equal steps of their own arc length (the
  closing segment too for a closed curve), against ``RESAMPLE`` points of the curve
  from each of ``SHIFTS`` starting places, either sense; a closed curve's targets
  cover the whole curve, an open one's each of :data:`FRACTIONS` of it;
* the similarity ``z ↦ α z + β`` (complex) of least squares, whose residual is
  ``Σ|t_c|² − |Σ conj(c_c) t_c|² / Σ|c_c|²`` (centred points): the shape error,
  measured against the targets' own spread.

The best matches, placed by their similarity at the curve's crank angle zero, are the
start four-bars (``A, B, C, D, P`` in the targets' plane); :mod:`.starts` carries
them into the file's design space (pins and, where point parameters let it move, the
coupler point) and refines them with the rest.
"""

from __future__ import annotations

import numpy as np

#: Four-bars drawn for the atlas, and the crank angles sampled on each curve.
CURVES, ANGLES = 4000, 96
#: Points of each curve at equal arc length, and of the targets.
SAMPLES, RESAMPLE = 192, 32
#: Starting places tried along each curve (every ``SAMPLES // SHIFTS``-th point).
SHIFTS = 32
#: Shares of the curve's length an open target may cover.
FRACTIONS = (0.2, 0.3, 0.45, 0.6, 0.8)


def _draw(rng, count: int, need: float) -> np.ndarray:
    """``(N, 6)`` normalised four-bars ``(a, b, c, u, v, branch)``, ground 1: Grashof
    crank-rockers (the crank ``a`` the shortest link) whose least transmission angle
    is at least ``need`` (rad); ``(u, v)`` the coupler point from ``B`` along and to
    the left of ``B → C``."""
    out = []
    while sum(len(o) for o in out) < count:
        a = rng.uniform(0.05, 0.7, 4 * count)
        b, c = np.exp(rng.uniform(np.log(0.25), np.log(3.0), (2, 4 * count)))
        links = np.stack([a, b, c, np.ones_like(a)], 1)
        order = np.sort(links, axis=1)
        grashof = order[:, 0] + order[:, 3] <= order[:, 1] + order[:, 2]
        crank = a <= links.min(axis=1)
        bc = 2 * b * c
        near = np.arccos(np.clip((b * b + c * c - (1 - a) ** 2) / bc, -1, 1))
        far = np.arccos(np.clip((b * b + c * c - (1 + a) ** 2) / bc, -1, 1))
        keep = grashof & crank & (np.minimum(near, np.pi - far) >= need)
        uv = rng.uniform(-1.5, 1.5, (2, 4 * count))
        branch = rng.choice([-1.0, 1.0], 4 * count)
        out.append(np.stack([a, b, c, uv[0], uv[1], branch], 1)[keep])
    return np.concatenate(out)[:count]


def _poses(bars: np.ndarray, phi: np.ndarray) -> tuple:
    """``B, C, P`` (complex, ``(N, m)``) of normalised four-bars at crank angles
    ``phi`` ``(m,)``."""
    a, b, c, u, v, branch = (bars[:, i, None] for i in range(6))
    pin = a * np.exp(1j * phi[None])
    gap = 1.0 - pin
    far = np.abs(gap)
    cosine = np.clip((b * b + far * far - c * c) / (2 * b * far), -1.0, 1.0)
    tip = pin + b * gap / far * np.exp(1j * branch * np.arccos(cosine))
    point = pin + (tip - pin) / b * (u + 1j * v)
    return pin, tip, point


def _resampled(z: np.ndarray, count: int, closed: bool) -> np.ndarray:
    """``count`` points at equal arc length along the polyline(s) ``z`` ``(..., m)``
    (closed: back to the first point, the last sample short of it)."""
    ring = np.concatenate([z, z[..., :1]], -1) if closed else z
    steps = np.abs(np.diff(ring, axis=-1))
    length = np.concatenate([np.zeros(z.shape[:-1] + (1,)), np.cumsum(steps, -1)], -1)
    total = length[..., -1:]
    at = np.linspace(0.0, 1.0, count, endpoint=not closed) * total
    flat_len = length.reshape(-1, length.shape[-1])
    flat_at = at.reshape(-1, count)
    flat_ring = ring.reshape(-1, ring.shape[-1])
    out = np.empty(flat_at.shape, dtype=complex)
    for k in range(len(flat_len)):
        out[k] = np.interp(flat_at[k], flat_len[k], flat_ring[k].real) + 1j * np.interp(
            flat_at[k], flat_len[k], flat_ring[k].imag
        )
    return out.reshape(at.shape)


def _windows(closed: bool) -> np.ndarray:
    """``(W, RESAMPLE)`` indices into a curve's ``SAMPLES`` points: each start
    place and (open) share of the curve."""
    starts = np.arange(0, SAMPLES, SAMPLES // SHIFTS)
    if closed:
        spans = [np.arange(RESAMPLE) * (SAMPLES // RESAMPLE)]
    else:
        spans = [
            np.round(np.linspace(0.0, f * SAMPLES, RESAMPLE)).astype(int)
            for f in FRACTIONS
        ]
    return np.array([(s + span) % SAMPLES for span in spans for s in starts])


def _selection(windows: np.ndarray, target: np.ndarray) -> tuple:
    """``(SAMPLES, W)`` matrices: how often each curve point is in each window, and
    the sum of the target points it meets there (so that a window's sums over its
    points are matrix products with the curves)."""
    count, length = windows.shape
    column = np.repeat(np.arange(count), length)
    chosen = np.zeros((SAMPLES, count))
    np.add.at(chosen, (windows.ravel(), column), 1.0)
    weights = np.zeros((SAMPLES, count), dtype=complex)
    np.add.at(weights, (windows.ravel(), column), np.tile(target, count))
    return chosen, weights


def matches(goals, closed: bool, need: float, seed: int, count: int) -> np.ndarray:
    """``(count, 5, 2)``: four-bars ``A, B, C, D, P`` (targets' plane, at rest) whose
    coupler curves best match the shape of the targets ``goals`` ``(k, 2)`` in
    order (module docstring), the best first; ``need`` the least transmission angle
    (rad). Each window's fit is in closed form from sums over its points (matrix
    products with the curves): ``Σ conj(c) t``, ``Σ c`` and ``Σ |c|²``."""
    rng = np.random.default_rng(seed)
    bars = _draw(rng, CURVES, need)
    phi = np.linspace(0.0, 2 * np.pi, ANGLES, endpoint=False)
    curves = _resampled(_poses(bars, phi)[2], SAMPLES, True)  # (N, SAMPLES)
    target = _resampled(goals[:, 0] + 1j * goals[:, 1], RESAMPLE, closed)
    middle = target.mean()
    target = target - middle
    spread = float(np.sum(np.abs(target) ** 2))
    windows = _windows(closed)
    chosen, forward = _selection(windows, target)
    _, backward = _selection(windows, target[::-1])
    sums = curves @ chosen  # (N, W)
    norm = np.abs(curves) ** 2 @ chosen - np.abs(sums) ** 2 / RESAMPLE + 1e-300
    rows = np.arange(len(bars))
    best = np.full(len(bars), np.inf)
    fits = np.zeros((len(bars), 2), dtype=complex)
    mirrored = np.zeros(len(bars), dtype=bool)
    for mirror in (False, True):
        shapes = np.conj(curves) if mirror else curves
        centre = (np.conj(sums) if mirror else sums) / RESAMPLE
        for weights in (forward, backward):
            dot = np.conj(shapes) @ weights  # Σ conj(c) t over each window
            residual = spread - np.abs(dot) ** 2 / norm  # (N, W)
            w = np.argmin(residual, axis=1)
            r = residual[rows, w]
            better = r < best
            alpha = dot[rows, w] / norm[rows, w]
            beta = middle - alpha * centre[rows, w]
            best = np.where(better, r, best)
            fits = np.where(better[:, None], np.stack([alpha, beta], 1), fits)
            mirrored = np.where(better, mirror, mirrored)
    chosen_bars = np.argsort(best)[:count]
    pin, tip, point = (x[:, 0] for x in _poses(bars[chosen_bars], np.zeros(1)))
    size = len(chosen_bars)
    joints = np.stack([np.zeros(size), pin, tip, np.ones(size), point], 1)
    joints = np.where(mirrored[chosen_bars, None], np.conj(joints), joints)
    world = fits[chosen_bars, :1] * joints + fits[chosen_bars, 1:]
    return np.stack([world.real, world.imag], -1)
