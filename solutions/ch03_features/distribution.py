"""Exercise 3.12: keypoints spread over the image (grid), and two published alternatives that also pass
(plain ANMS, ORB-SLAM's quadtree)."""
from __future__ import annotations

import numpy as np


# ============================================================ 3.12 distribution ====

def distribute_keypoints(kps: np.ndarray, scores: np.ndarray, image_size: tuple[int, int], n: int,
                         cells: tuple[int, int] = (8, 8)) -> np.ndarray:
    """Exercise 3.12: pick n keypoints spread over the image. The best of every cell, then the second best of
    every cell, and so on (strongest first within a round) — ORB-SLAM's idea without the quadtree.

    kps: (N, 2) (x, y); scores: (N,) higher is better; image_size: (width, height); cells:
    (columns, rows) of the grid. Returns (min(n, N),) int64 indices into kps.
    """
    kps, scores = np.asarray(kps, float), np.asarray(scores, float)
    W, H = image_size
    cx = np.clip((kps[:, 0] + 0.5) * cells[0] // W, 0, cells[0] - 1).astype(int)
    cy = np.clip((kps[:, 1] + 0.5) * cells[1] // H, 0, cells[1] - 1).astype(int)
    cell = cy * cells[0] + cx
    order = np.lexsort((-scores, cell))  # by cell, strongest first inside a cell
    sorted_cell = cell[order]
    start = np.searchsorted(sorted_cell, sorted_cell, side="left")
    rank = np.empty(len(kps), int)
    rank[order] = np.arange(len(kps)) - start  # 0 for the best of its cell, 1 for the second, ...
    pick = np.lexsort((-scores, rank))[:n]
    return pick.astype(np.int64)


def distribute_anms(kps: np.ndarray, scores: np.ndarray, image_size: tuple[int, int], n: int,
                    cells: tuple[int, int] = (8, 8), c: float = 1.0) -> np.ndarray:
    """Exercise 3.12, an alternative that also passes: adaptive non-maximal suppression (Brown, Szeliski &
    Winder 2005): each keypoint's suppression
    radius is the distance to the nearest keypoint that is clearly stronger (score_i < c score_j);
    keep the n largest radii (ties: stronger first). c = 1 is plain ANMS, Brown et al. use c = 0.9.
    `image_size` and `cells` are unused (the signature of 3.12). (min(n, N),) int64 indices."""
    kps, scores = np.asarray(kps, float)[:, :2], np.asarray(scores, float)
    order = np.argsort(-scores, kind="stable")
    p, s = kps[order], scores[order]
    radius = np.full(len(p), np.inf)
    for i in range(1, len(p)):  # only stronger keypoints (earlier in `order`) can suppress point i
        stronger = s[:i] * c > s[i]
        if stronger.any():
            radius[i] = np.sqrt(np.min(np.sum((p[:i][stronger] - p[i]) ** 2, axis=1)))
    pick = np.lexsort((-s, -radius))[:n]
    return order[pick].astype(np.int64)


def distribute_quadtree(kps: np.ndarray, scores: np.ndarray, image_size: tuple[int, int], n: int,
                        cells: tuple[int, int] = (8, 8)) -> np.ndarray:
    """Exercise 3.12, an alternative that also passes: ORB-SLAM's quadtree. Split the most populated node
    into four until there are n nodes (or no
    node with two keypoints is left), keep the strongest keypoint of every node, then fill up to n
    with the strongest of the rest. `cells` is unused (the signature of 3.12). (min(n, N),) int64."""
    kps, scores = np.asarray(kps, float)[:, :2], np.asarray(scores, float)
    W, H = image_size
    nodes = [(-0.5, -0.5, W - 0.5, H - 0.5, np.arange(len(kps)))]  # (x0, y0, x1, y1, members)
    while len(nodes) < n and any(len(m) > 1 for *_, m in nodes):
        # one round: split every node that holds two or more keypoints, the most populated first,
        # until there are n nodes (breadth first, so sparse regions are divided too)
        nodes.sort(key=lambda node: -len(node[4]))
        done, todo = [], nodes
        while todo:
            x0, y0, x1, y1, m = node = todo.pop(0)
            if len(m) < 2 or len(done) + len(todo) + 1 >= n:
                done.append(node)
                continue
            xm, ym = (x0 + x1) / 2, (y0 + y1) / 2
            right, below = kps[m, 0] >= xm, kps[m, 1] >= ym
            for r, b, box in ((False, False, (x0, y0, xm, ym)), (True, False, (xm, y0, x1, ym)),
                              (False, True, (x0, ym, xm, y1)), (True, True, (xm, ym, x1, y1))):
                sub = m[(right == r) & (below == b)]
                if len(sub):
                    done.append((*box, sub))
        nodes = done
    best = np.array([m[np.argmax(scores[m])] for *_, m in nodes], int)
    best = best[np.argsort(-scores[best], kind="stable")][:n]
    rest = np.setdiff1d(np.arange(len(kps)), best)
    rest = rest[np.argsort(-scores[rest], kind="stable")][:n - len(best)]
    return np.r_[best, rest].astype(np.int64)
