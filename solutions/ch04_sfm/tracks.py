"""Chapter 4, 4.11 — tracks by union-find over (image, keypoint) nodes.
"""
from __future__ import annotations

import numpy as np



class _UnionFind:
    """Disjoint sets over 0..n-1 with path halving and union by size."""

    def __init__(self, n: int):
        self.parent = list(range(n))
        self.size = [1] * n

    def find(self, a: int) -> int:
        parent = self.parent
        while parent[a] != a:
            parent[a] = parent[parent[a]]
            a = parent[a]
        return a

    def union(self, a: int, b: int) -> None:
        a, b = self.find(a), self.find(b)
        if a == b:
            return
        if self.size[a] < self.size[b]:
            a, b = b, a
        self.parent[b] = a
        self.size[a] += self.size[b]


def build_tracks(matches: dict) -> list[dict[int, int]]:
    """Exercise 4.11: Tracks from pairwise matches: connected components of the graph whose nodes are
    (image, keypoint) and whose edges are the matches, found with union-find.

    matches: {(i, j): (M, 2) int array of keypoint-index pairs (k_i, k_j)}. A component with two
    different keypoints of one image is inconsistent (some match in it is wrong, and we cannot
    tell which): it is dropped whole, as are components with fewer than 2 images.
    Returns a list of {image: keypoint} dicts, ordered by their smallest (image, keypoint) node.
    """
    node_of: dict[tuple[int, int], int] = {}
    edges = []
    for (i, j), m in matches.items():
        for a, b in np.asarray(m, np.int64).reshape(-1, 2).tolist():
            na = node_of.setdefault((i, a), len(node_of))
            nb = node_of.setdefault((j, b), len(node_of))
            edges.append((na, nb))
    uf = _UnionFind(len(node_of))
    for a, b in edges:
        uf.union(a, b)
    groups: dict[int, dict[int, int]] = {}
    bad: set[int] = set()
    for (img, kp), node in sorted(node_of.items()):
        root = uf.find(node)
        track = groups.setdefault(root, {})
        if track.get(img, kp) != kp:
            bad.add(root)
        track[img] = kp
    return [tr for root, tr in groups.items() if root not in bad and len(tr) >= 2]


def consistent_tracks(matches: dict) -> list[dict[int, int]]:
    """Tracks as `build_tracks` makes them, except that a component holding two keypoints of one image is split
    rather than dropped whole: the matches are joined strongest image pair first (pairs ordered by their number
    of verified matches), and a union that would put two keypoints of one image into one track is refused,
    so the later, weaker match (the likelier wrong one) is the one left out (Kruskal's order with a conflict
    test). Used by `incremental_sfm(..., split_tracks=True)`; exercise 4.11 asks for `build_tracks`.

    Why: on a facade, repeated windows make a few wrong matches that pass F-RANSAC, and each one joins two
    tracks into an inconsistent component. `build_tracks` drops 28.5 % of the matched keypoints of the 11
    Sceaux Castle photos that way (8.3 % on Sacre Coeur), and a larger set of one building loses more: an
    image seeing too few points cannot be registered. Same input and output as `build_tracks`.
    """
    node_of: dict[tuple[int, int], int] = {}
    edges = []
    for (i, j), m in sorted(matches.items(), key=lambda kv: -len(kv[1])):
        for a, b in np.asarray(m, np.int64).reshape(-1, 2).tolist():
            edges.append((node_of.setdefault((i, a), len(node_of)), node_of.setdefault((j, b), len(node_of))))
    image_of = [img for img, _ in node_of]
    uf = _UnionFind(len(node_of))
    images = [{img} for img in image_of]                 # images in each set (valid at its root)
    for a, b in edges:
        ra, rb = uf.find(a), uf.find(b)
        if ra == rb or images[ra] & images[rb]:
            continue                                     # already joined, or a conflict: refuse
        uf.union(ra, rb)
        root = uf.find(ra)
        images[root] = images[ra] | images[rb]
    groups: dict[int, dict[int, int]] = {}
    for (img, kp), node in sorted(node_of.items()):
        groups.setdefault(uf.find(node), {})[img] = kp
    return [tr for tr in groups.values() if len(tr) >= 2]
