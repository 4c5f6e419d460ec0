"""Chapter 4, section 4.11 — tracks: connected components of the match graph over (image, keypoint).

Oracle: scipy.sparse.csgraph.connected_components; the stand-in's union-find (graders.oracles.sfm_standin)
is an independent second implementation.
"""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, register


def gt_build_tracks(matches: dict) -> list[dict[int, int]]:
    """Connected components of the match graph over (image, keypoint) nodes (scipy.sparse.csgraph);
    components with two keypoints in one image, or fewer than two observations, are dropped."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    ids: dict[tuple[int, int], int] = {}
    edges = []
    for (i, j), m in matches.items():
        for a, b in np.asarray(m, int).reshape(-1, 2):
            u = ids.setdefault((int(i), int(a)), len(ids))
            v = ids.setdefault((int(j), int(b)), len(ids))
            edges.append((u, v))
    if not edges:
        return []
    e = np.array(edges)
    g = coo_matrix((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(len(ids), len(ids)))
    _, label = connected_components(g, directed=False)
    groups: dict[int, list[tuple[int, int]]] = {}
    for node, k in ids.items():
        groups.setdefault(label[k], []).append(node)
    tracks = []
    for nodes in groups.values():
        images = [i for i, _ in nodes]
        if len(nodes) >= 2 and len(set(images)) == len(images):
            tracks.append({i: kp for i, kp in sorted(nodes)})
    return tracks


def _track_set(tracks) -> set[frozenset]:
    return {frozenset((int(i), int(k)) for i, k in tr.items()) for tr in tracks}


def _convert_tracks(out, case):
    if out is None:
        raise OutputError("returned None: is a `return` missing?")
    try:
        tracks = [dict(tr) for tr in out]
        sets = [frozenset((int(i), int(k)) for i, k in tr.items()) for tr in tracks]
    except Exception:
        raise OutputError("expected a list of dicts {image index: keypoint index}") from None
    if len(set(sets)) != len(sets):
        raise OutputError("the same track is returned twice")
    return tracks


def _metric_tracks(tracks, expected) -> float:
    """Number of tracks in one answer but not the other (as sets of (image, keypoint))."""
    return float(len(_track_set(tracks) ^ _track_set(expected)))


def track_problem(rng: np.random.Generator, n_images: int = 6, n_points: int = 150, keep: float = 0.7, wrong: int = 6,
                  chain: bool = False) -> dict:
    """Matches between images for points seen in 2..n_images images (shuffled keypoint indices, plus
    keypoints seen once). Each pair that shares a point keeps its match with probability `keep`
    (some tracks are then connected only through other images); `wrong` matches join two different
    points (their tracks become inconsistent when two keypoints of one image end up together).
    chain: each point is matched only between consecutive images (i, i+1)."""
    obs = []
    for p in range(n_points):
        k = rng.integers(2, n_images + 1)
        obs.append(np.sort(rng.choice(n_images, k, replace=False)))
    kp_of: list[dict[int, int]] = [dict() for _ in range(n_points)]
    for i in range(n_images):
        pts = [p for p in range(n_points) if i in obs[p]]
        idx = rng.permutation(len(pts) + rng.integers(5, 30))      # extra keypoints nobody matches
        for p, k in zip(pts, idx):
            kp_of[p][i] = int(k)
    matches: dict[tuple[int, int], list] = {}
    for p in range(n_points):
        imgs = obs[p]
        pairs = [(imgs[a], imgs[a + 1]) for a in range(len(imgs) - 1)] if chain else \
            [(a, b) for ai, a in enumerate(imgs) for b in imgs[ai + 1:]]
        if not chain:
            pairs = [pr for pr in pairs if rng.random() < keep] or [pairs[0]]
        for a, b in pairs:
            matches.setdefault((int(a), int(b)), []).append((kp_of[p][a], kp_of[p][b]))
    for _ in range(wrong):                                          # a wrong match joins two points
        p, q = rng.choice(n_points, 2, replace=False)
        common = [(a, b) for a in kp_of[p] for b in kp_of[q] if a < b] + \
                 [(b, a) for a in kp_of[p] for b in kp_of[q] if b < a]
        if not common:
            continue
        a, b = common[rng.integers(len(common))]
        ka = kp_of[p][a] if a in kp_of[p] else kp_of[q][a]
        kb = kp_of[q][b] if b in kp_of[q] else kp_of[p][b]
        matches.setdefault((int(a), int(b)), []).append((ka, kb))
    return {k: np.array(v, int).reshape(-1, 2) for k, v in sorted(matches.items())}


def cases_build_tracks(rng: np.random.Generator) -> list[Case]:
    out = []
    for name, kw in [("6 images, 150 points, every pair matched", dict(keep=1.0, wrong=0)),
                     ("6 images, 30 % of the pairwise matches missing (tracks join through other images)",
                      dict(keep=0.7, wrong=0)),
                     ("chains only: each point matched between consecutive images", dict(chain=True, wrong=0)),
                     ("8 wrong matches merge pairs of points (drop the inconsistent tracks)",
                      dict(keep=0.8, wrong=8, n_images=8, n_points=200))]:
        m = track_problem(rng, **kw)
        exp = gt_build_tracks(m)
        kept = {node for tr in _track_set(exp) for node in tr}
        dropped = {(int(i), int(k)) for (i, j), mm in m.items() for a, b in mm for (i, k) in ((i, a), (j, b))} - kept
        # exact: tracks compared as sets of (image, keypoint) sets; 0 tracks may differ.
        out.append(Case(f"{name}: {len(exp)} tracks", (m,), exp, _metric_tracks, 0, "tracks differ",
                        convert=_convert_tracks, info={"dropped": dropped}))
    return out


def _track_hints():
    def merged(c, out):
        ts = _track_set(out)
        return any(len({i for i, _ in tr}) < len(tr) for tr in ts)

    def not_transitive(c, out):
        return len(out) > len(c.expected) and not touches_dropped(c, out)

    def touches_dropped(c, out):
        dropped = c.info["dropped"]
        return any(node in dropped for tr in _track_set(out) for node in tr)
    return [Hint("a track holds two keypoints of the same image: two 3D points were merged by a wrong match — drop "
                 "such tracks.", merged),
            Hint("some tracks join two 3D points: a wrong match put two keypoints of one image in the same connected "
                 "component — drop the whole component, not just the clashing observations.", touches_dropped),
            Hint("tracks are not joined through other images: a → b and b → c belong to one track even without a "
                 "match a → c. Use union-find over (image, keypoint) nodes.", not_transitive)]


TRACK_HINTS = _track_hints()


register(
    Exercise(id="4.11", title="Tracks by union-find", name="build_tracks", kind="code", points=3,
             cases=cases_build_tracks, hints=TRACK_HINTS, fallback=gt_build_tracks, arg_names=("matches",)),
)
