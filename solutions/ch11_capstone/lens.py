"""11.11: the smudge as the disc that best explains today's keypoint counts as the baseline's times the part of
each cell outside it (least squares, coarse-to-fine grid search; numpy only)."""
from __future__ import annotations

import numpy as np


def _counts(kps, shape, cell):
    h, w = shape
    c = np.zeros((h // cell, w // cell))
    for k in kps:
        k = np.asarray(k, float)
        i = np.clip((k[:, 1] // cell).astype(int), 0, h // cell - 1)
        j = np.clip((k[:, 0] // cell).astype(int), 0, w // cell - 1)
        np.add.at(c, (i, j), 1)
    return c


def find_smudge(before, now, shape, cell=8):
    hb, hn = _counts(before, shape, cell), _counts(now, shape, cell)
    h, w = shape
    yc = (np.arange(h // cell) + 0.5) * cell
    xc = (np.arange(w // cell) + 0.5) * cell

    def cost(cx, cy, r):    # soft disc edge over one cell approximates the covered fraction
        d = np.hypot(yc[:, None] - cy, xc[None] - cx)
        inside = np.clip((r - d) / cell + 0.5, 0, 1)
        return np.sum((hn - hb * (1 - inside)) ** 2)

    best = (w / 2, h / 2, 40.0)
    for step in (16.0, 4.0, 1.0):
        cx0, cy0, r0 = best
        span = 1 if step < 16 else None
        xs = np.arange(16, w - 15, step) if span is None else cx0 + step * np.arange(-4, 5)
        ys = np.arange(16, h - 15, step) if span is None else cy0 + step * np.arange(-4, 5)
        rs = np.arange(24, 100, step) if span is None else r0 + step * np.arange(-4, 5)
        best = min(((x, y, r) for x in xs for y in ys for r in rs), key=lambda p: cost(*p))
    return np.array([best[0], best[1], best[2] / 0.9])   # features die inside ~0.9 r (the soft rim keeps some)
