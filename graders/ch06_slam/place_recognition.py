"""Chapter 6, place recognition: 6.14 `bow_scores` (k-means vocabulary, tf-idf, DBoW2's L1 score, top-k).

The synthetic loop sequence (`loop_sequence`, shared with 6.15): a camera goes twice round a loop of
places; each place shows a window of landmarks, each landmark a prototype descriptor (float, D = 32),
each sighting the prototype plus noise, some sightings dropped; a few "ubiquitous" landmarks (floor,
ceiling texture) are seen everywhere, which tf-idf must discount. The first lap is the database, the
second the queries, so every query's true revisits are known (the database frames within two places).

Oracles: the DBoW2 score written out in numpy (s = 1 − ½‖v₁/‖v₁‖₁ − v₂/‖v₂‖₁‖₁, tf-idf weights with
idf = log(N / N_w) over the database images: Gálvez-López & Tardós, T-RO 2012) for given vocabularies,
and scipy's `kmeans2` (k-means++) vocabulary + that score for the retrieval a trained vocabulary reaches.
"""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, register

D = 32   # descriptor length


# ----------------------------------------------------------------- the loop sequence

def loop_sequence(rng: np.random.Generator,
                  n_places: int = 40, per_place: int = 8, window: int = 2, noise: float = 0.35,
                  keep: float = 0.7, n_ubiquitous: int = 8, aliased: int = 0) -> dict:
    """Two laps round a loop of `n_places` places. Place p owns `per_place` landmarks; frame at place p sees
    the landmarks of places p-window..p+window (each kept with probability `keep`) and the ubiquitous ones
    (several times each). `aliased` pairs of far-apart places share their landmarks' prototypes (perceptual
    aliasing: identical-looking places, e.g. two identical corridors), which retrieval alone cannot tell apart.
    Returns db (list of (n_i, D)), queries (list), place_db, place_q (ints), the landmarks each frame saw
    (ids, for geometric verification), and alias (place -> its look-alike or -1)."""
    n_lm = n_places * per_place
    proto = rng.normal(0, 1, (n_lm + n_ubiquitous, D))
    alias = np.full(n_places, -1)
    if aliased:
        order = rng.permutation(n_places)
        for a, b in order[:2 * aliased].reshape(-1, 2):
            if min(abs(a - b), n_places - abs(a - b)) <= 2 * window + 2:
                continue   # too close: their windows overlap anyway
            alias[a], alias[b] = b, a
            proto[b * per_place:(b + 1) * per_place] = proto[a * per_place:(a + 1) * per_place]
    ubiq = n_lm + np.arange(n_ubiquitous)

    def frame(p):
        places = (p + np.arange(-window, window + 1)) % n_places
        ids = (places[:, None] * per_place + np.arange(per_place)).ravel()
        ids = ids[rng.random(len(ids)) < keep]
        ids = np.r_[ids, np.repeat(ubiq, 3)]
        return proto[ids] + rng.normal(0, noise, (len(ids), D)), ids

    db, q, ids_db, ids_q = [], [], [], []
    for p in range(n_places):
        d, i = frame(p)
        db.append(d), ids_db.append(i)
    place_q = rng.permutation(n_places)
    for p in place_q:
        d, i = frame(p)
        q.append(d), ids_q.append(i)
    return {"db": db, "queries": q, "place_db": np.arange(n_places), "place_q": place_q, "ids_db": ids_db,
            "ids_q": ids_q, "alias": alias, "n_places": n_places, "prototypes": proto}


def true_revisits(seq: dict, radius: int = 2) -> np.ndarray:
    """(Q, N) bool: database frame i is a true revisit of query j (within `radius` places round the loop)."""
    d = np.abs(seq["place_q"][:, None] - seq["place_db"][None, :])
    d = np.minimum(d, seq["n_places"] - d)
    return d <= radius


# ----------------------------------------------------------------- oracle

def _words(desc: np.ndarray, V: np.ndarray) -> np.ndarray:
    d2 = (desc ** 2).sum(1)[:, None] - 2 * desc @ V.T + (V ** 2).sum(1)[None, :]
    return np.argmin(d2, axis=1)


def _histograms(descs, V) -> np.ndarray:
    return np.array([np.bincount(_words(d, V), minlength=len(V)) for d in descs], float)


def gt_bow_scores(db, queries, V, top_k, idf_from="images", normalise="l1", half=True, use_idf=True,
                  signed=False):
    """DBoW2's scoring with a flat vocabulary V (W, D) (and the slips of the hint models)."""
    H_db, H_q = _histograms(db, V), _histograms(queries, V)
    N = len(db)
    n_w = (H_db > 0).sum(0) if idf_from == "images" else H_db.sum(0)
    with np.errstate(divide="ignore"):
        idf = np.where(n_w > 0, np.log(N / np.maximum(n_w, 1)), 0.0) if use_idf else np.ones(len(V))

    def weigh(H):
        v = H / np.maximum(H.sum(1, keepdims=True), 1) * idf
        # (`signed`: the L1 norm as a plain sum, as code written for non-negative weights computes it)
        l1 = v.sum(1, keepdims=True) if signed else np.abs(v).sum(1, keepdims=True)
        norm = l1 if normalise == "l1" else np.linalg.norm(v, axis=1, keepdims=True)
        return v / np.where(norm > 0, norm, 1)

    A, B = weigh(H_q), weigh(H_db)
    S = 1 - (0.5 if half else 1.0) * np.abs(A[:, None, :] - B[None, :, :]).sum(2)
    top = np.argsort(-S, axis=1, kind="stable")[:, :top_k]
    return S, top


def scipy_vocabulary(db, n_words: int, seed: int = 0) -> np.ndarray:
    from scipy.cluster.vq import kmeans2

    X = np.vstack(db)
    V, _ = kmeans2(X, n_words, minit="++", iter=10, seed=seed)
    return V


def scipy_bow_scores(db, queries, vocabulary, top_k, seed=0):
    """Stand-in for 6.14: scipy's k-means++ vocabulary (when `vocabulary` is a word count), then DBoW2's score."""
    V = scipy_vocabulary(db, int(vocabulary), seed) if np.ndim(vocabulary) == 0 else np.asarray(vocabulary, float)
    return gt_bow_scores(db, queries, V, top_k)


def retrieval_quality(top: np.ndarray, truth: np.ndarray) -> tuple[float, float]:
    """(precision@k: share of the returned frames that are true revisits, recall@k: share of the queries
    with a true revisit among their top k)."""
    hit = np.take_along_axis(truth, top, axis=1)
    return float(hit.mean()), float(hit.any(1).mean())


# ----------------------------------------------------------------- exercise

def _convert(out, case):
    nq, n = len(case.args[1]), len(case.args[0])
    k = case.args[3]
    if not isinstance(out, (tuple, list)) or len(out) != 2:
        raise OutputError("expected (S (Q, N) scores, top (Q, k) indices)")
    try:
        S, top = np.asarray(out[0], float), np.asarray(out[1])
    except (TypeError, ValueError):
        raise OutputError("expected numeric arrays (S, top)") from None
    if S.shape != (nq, n) or not np.isfinite(S).all():
        raise OutputError(f"S: expected finite scores of shape ({nq}, {n}), got {S.shape}")
    if top.shape != (nq, k) or not np.issubdtype(top.dtype, np.integer) or top.min() < 0 or top.max() >= n:
        raise OutputError(f"top: expected integer database indices of shape ({nq}, {k})")
    return S, top


def _metric_scores(out, expected):
    """Worst score error; 1 if `top` is not the k best of the true scores, best first (ties allowed)."""
    S, top = out
    S_true = expected[0]
    err = float(np.abs(S - S_true).max())
    got = np.take_along_axis(S_true, top, axis=1)
    kth = -np.sort(-S_true, axis=1)[:, :top.shape[1]]
    if np.abs(got - kth).max() > 1e-9:
        err = max(err, 1.0)
    return err


def _metric_retrieval(out, expected):
    """How far the learner's retrieval falls short of the scipy vocabulary's: the worse of precision@k and
    recall@k, oracle minus learner."""
    p, r = retrieval_quality(out[1], expected["truth"])
    return max(expected["precision"] - p, expected["recall"] - r, 0.0)


TOL_SCORES = 1e-9   # float64 sums of <= 200 terms: ~1e-15; every slip below moves a score by > 1e-3
# A trained vocabulary is judged by what it retrieves. 0.15: over k-means++ restarts on one sequence the
# oracle's own precision@5 spans up to 0.09 (0.785-0.875, 6 restarts x 3 sequences) and recall@5 is 1.0;
# a vocabulary of random descriptors (k-means never iterated) falls 0.3-0.4 short.
TOL_RETRIEVAL = 0.15


def cases_bow_scores(rng: np.random.Generator):
    for i, (n_places, n_words) in enumerate([(16, 24), (30, 48)]):
        seq = loop_sequence(rng, n_places=n_places)
        V = seq["prototypes"][rng.choice(len(seq["prototypes"]), n_words, replace=False)] \
            + rng.normal(0, 0.1, (n_words, D))
        args = (seq["db"], seq["queries"], V, 5)
        yield Case(f"given vocabulary ({n_words} words), {n_places} places: scores and top 5 vs DBoW2's L1 score",
                   args, gt_bow_scores(*args), _metric_scores, TOL_SCORES, "score", convert=_convert,
                   key=f"scores-{i + 1}", tags=("scores",))
    seq = loop_sequence(rng, n_places=40)
    truth = true_revisits(seq)
    seed = int(rng.integers(2 ** 31))
    V = scipy_vocabulary(seq["db"], 64, seed)
    _, top = gt_bow_scores(seq["db"], seq["queries"], V, 5)
    p, r = retrieval_quality(top, truth)
    yield Case("vocabulary trained by your k-means (64 words), 40-place loop: precision@5 and recall@5 within 0.15 "
               "of scipy's k-means++", (seq["db"], seq["queries"], 64, 5), {"truth": truth, "precision": p,
                                                                           "recall": r},
               _metric_retrieval, TOL_RETRIEVAL, "short", convert=_convert, kwargs={"seed": seed % 1000},
               key="trained", tags=("trained",))


def _scores_like(**kw):
    def when(case, out):
        if "scores" not in case.tags:
            return False
        return any(float(np.abs(out[0] - gt_bow_scores(*case.args, **kw, signed=signed)[0]).max()) < 1e-9
                   for signed in (False, True))
    return when


HINTS = [
    Hint("your scores ignore idf: words seen in every image (the floor, the ceiling) dominate. Weight each word by "
         "idf = log(N / N_w), N_w the number of database images containing it.", _scores_like(use_idf=False)),
    Hint("your idf counts occurrences of a word, not the images containing it: N_w is the number of database "
         "images in which word w appears at least once.", _scores_like(idf_from="occurrences")),
    Hint("your vectors are normalised by their L2 norm: DBoW2's L1 score normalises each by its L1 norm, "
         "s = 1 − ½‖v₁/‖v₁‖₁ − v₂/‖v₂‖₁‖₁.", _scores_like(normalise="l2")),
    Hint("your scores lack the ½: s = 1 − ½‖a − b‖₁ lies in [0, 1] (1 for identical vectors, 0 for disjoint ones).",
         _scores_like(half=False)),
    Hint("your top k are the *least* similar frames: sort the scores in decreasing order.",
         lambda case, out: bool("scores" in case.tags and np.array_equal(
             out[1], np.argsort(out[0], axis=1, kind="stable")[:, :case.args[3]])
             and not np.array_equal(out[1], np.argsort(-out[0], axis=1, kind="stable")[:, :case.args[3]]))),
]


register(
    Exercise(
        id="6.14",
        title="Bag-of-words place recognition: k-means vocabulary, tf-idf, L1 score, top-k",
        name="bow_scores",
        kind="code",
        points=3,
        cases=cases_bow_scores,
        hints=HINTS,
        fallback=scipy_bow_scores,
        arg_names=("db", "queries", "vocabulary", "top_k"),
        timeout=30.0,
    ),
)
