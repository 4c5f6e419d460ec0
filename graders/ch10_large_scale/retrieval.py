"""10.6 — a vocabulary tree: hierarchical k-means, tree descent, tf-idf, L1 scores, an inverted file.

Three kinds of case. (1) Places: a set of images of known places — textured planes (crops of the
skimage textures) rendered by graders.kit.scene under new viewpoints (homographies) and lighting (gain,
gamma, noise); SIFT descriptors from OpenCV. The learner's ranking is judged by mAP and recall@k
against the labels, beside brute-force matching (ratio-test matches of every query with every database
image), the quadratic baseline retrieval replaces. (2) Structured words: descriptors drawn around
k^L centres nested k per level, so far apart that hierarchical k-means (k-means++) recovers exactly
those words whatever its labels; the grader knows every descriptor's word, so the tf-idf L1 scores are
exact and the slips (idf of descriptors instead of images, L2 instead of L1, no idf, one level) show. (3) The same
words with queries holding descriptors on the boundary between two branches (boundary_problem): the tree's descent
and a flat vocabulary's nearest leaf disagree there, so a flat k-means with brute-force assignment shows too.

Scores (the spec): for image I with word counts n_w, v_w = n_w · idf_w, idf_w = ln(N / N_w) (N database
images, N_w of them containing w; w in no database image weighs 0); v̂ = v / ‖v‖₁;
score(q, d) = 1 − ½ ‖q̂ − d̂‖₁ = Σ_w min(q̂_w, d̂_w) in [0, 1] (0 when a vector is all zero).
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

from graders.core.convert import OutputError
from graders.core.engine import Case, Exercise, like, register, shared_run
from graders.kit.scene import TEXTURES, look_at, render_plane, rotation_about, texture
from graders.core.memo import cached

W, H = 160, 120                                  # rendered views: small, so SIFT costs ~25 ms an image
RICH = ("astronaut", "brick", "camera", "chelsea", "coffee", "coins", "gravel", "immunohistochemistry",
        "page", "rocket", "text", "hubble_deep_field", "retina", "moon")
assert set(RICH) <= set(TEXTURES)


# ------------------------------------------------------------------ places: renders of known places

def _view(rng: np.random.Generator, crop: np.ndarray) -> np.ndarray:
    """One photo of a place: the crop on a 1 m plane, seen from 0.9-1.3 m, tilted 0-30°, rolled ±20°,
    with a gain of 0.6-1.4, a gamma of 0.7-1.4 and sensor noise."""
    f = W / 2 / np.tan(np.radians(30))
    K = np.array([[f, 0, (W - 1) / 2], [0, f, (H - 1) / 2], [0, 0, 1.0]])
    centre = np.array([0.5, 0.5 * crop.shape[0] / crop.shape[1], 0.0])
    tilt = rotation_about(np.r_[rng.normal(size=2), 0.0], np.radians(rng.uniform(0, 30)))
    target = centre + np.r_[rng.uniform(-0.05, 0.05, 2), 0.0]
    R, t = look_at(target + rng.uniform(0.9, 1.3) * tilt @ np.array([0.0, 0.0, -1.0]), target)
    roll = rotation_about([0.0, 0.0, 1.0], np.radians(rng.uniform(-20, 20)))
    img, _ = render_plane(crop, K, roll @ R, roll @ t, None, W, H)
    img = rng.uniform(0.6, 1.4) * np.clip(img, 0, 1) ** rng.uniform(0.7, 1.4) + rng.normal(0, 0.01, img.shape)
    return np.clip(img * 255, 0, 255).astype(np.uint8)


def place_images(rng: np.random.Generator, n_places: int = 10, views: int = 4) -> dict:
    """Photos of `n_places` places, `views` each: a place is a 256 x 192 crop of a texture (resampled to 512 x 384) (two places
    may share a texture: similar façades). The first view of each place is the query, the rest the database.
    Returns db_images, query_images (lists of (H, W) uint8), db_labels: (N,), query_labels: (Q,)."""
    db, q, dl, ql = [], [], [], []
    for p in range(n_places):
        tex = texture(RICH[rng.integers(len(RICH))], size=(512, 384))   # every texture at one size
        r0, c0 = rng.integers(0, tex.shape[0] - 192), rng.integers(0, tex.shape[1] - 256)
        crop = np.ascontiguousarray(tex[r0:r0 + 192, c0:c0 + 256])
        for v in range(views):
            (q if v == 0 else db).append(_view(rng, crop))
            (ql if v == 0 else dl).append(p)
    return {"db_images": db, "query_images": q, "db_labels": np.array(dl), "query_labels": np.array(ql)}


@lru_cache(maxsize=1)
def _sift():
    import cv2
    return cv2.SIFT_create(nfeatures=150)


def sift_descriptors(images: list[np.ndarray]) -> list[np.ndarray]:
    """OpenCV SIFT (150 features at most) of each image: a list of (n_i, 128) float32 (n_i may be 0)."""
    out = []
    for img in images:
        _, d = _sift().detectAndCompute(img, None)
        out.append(np.zeros((0, 128), np.float32) if d is None else d.astype(np.float32))
    return out


def place_problem(rng: np.random.Generator, n_places: int = 10, views: int = 4) -> dict:
    """place_images plus their SIFT descriptors (db_descriptors, query_descriptors)."""
    P = place_images(rng, n_places, views)
    P["db_descriptors"] = sift_descriptors(P["db_images"])
    P["query_descriptors"] = sift_descriptors(P["query_images"])
    return P


def brute_force_scores(db: list[np.ndarray], queries: list[np.ndarray], ratio: float = 0.8) -> np.ndarray:
    """The quadratic baseline: score(q, d) = ratio-test matches of q's descriptors in d. (Q, N)."""
    S = np.zeros((len(queries), len(db)))
    for j, Dq in enumerate(queries):
        for i, Dd in enumerate(db):
            if len(Dq) == 0 or len(Dd) < 2:
                continue
            d2 = (Dq ** 2).sum(1)[:, None] - 2 * Dq @ Dd.T + (Dd ** 2).sum(1)[None]
            two = np.sqrt(np.maximum(np.partition(d2, 1, axis=1)[:, :2], 0))
            S[j, i] = np.sum(two[:, 0] < ratio * two[:, 1])
    return S


def average_precision(scores: np.ndarray, relevant: np.ndarray) -> float:
    """AP of one query: scores (N,) ranked high to low (ties by index), relevant (N,) bool."""
    order = np.argsort(-scores, kind="stable")
    hits = relevant[order]
    if not hits.any():
        return 0.0
    prec = np.cumsum(hits) / np.arange(1, len(hits) + 1)
    return float(prec[hits].mean())


def mean_ap(S: np.ndarray, db_labels: np.ndarray, q_labels: np.ndarray) -> float:
    return float(np.mean([average_precision(S[j], db_labels == q_labels[j]) for j in range(len(q_labels))]))


def recall_at_k(top: np.ndarray, db_labels: np.ndarray, q_labels: np.ndarray) -> float:
    """Fraction of queries with at least one image of their place among the returned top-k."""
    return float(np.mean([np.any(db_labels[top[j]] == q_labels[j]) for j in range(len(q_labels))]))


# ------------------------------------------------------------------ tf-idf scoring from known words

def tfidf_scores(db_words: list[np.ndarray], q_words: list[np.ndarray], n_words: int, idf: str = "images",
                 norm: str = "l1") -> np.ndarray:
    """The spec's scores from each descriptor's word (db_words[i]: (n_i,) ints). (Q, N).
    idf="images": ln(N / N_w) (the spec); "descriptors": ln(N / (descriptors of w + 1)) (a slip);
    "none": 1. norm="l1": 1 − ½‖q̂ − d̂‖₁ (the spec); "l2": cosine of L2-normalised vectors (a slip)."""
    N = len(db_words)
    counts = lambda words: np.bincount(np.asarray(words, int), minlength=n_words).astype(float)
    Cd, Cq = np.array([counts(w) for w in db_words]), np.array([counts(w) for w in q_words])
    Nw = (Cd > 0).sum(0)
    with np.errstate(divide="ignore"):
        w = {"images": np.where(Nw > 0, np.log(N / np.maximum(Nw, 1)), 0.0),
             "descriptors": np.log(N / (Cd.sum(0) + 1)),
             "none": np.ones(n_words)}[idf]
    Vd, Vq = Cd * w, Cq * w
    p = 1 if norm == "l1" else 2
    unit = lambda V: V / np.where(np.linalg.norm(V, p, axis=1, keepdims=True) > 0,
                                  np.linalg.norm(V, p, axis=1, keepdims=True), 1.0)
    Vd, Vq = unit(Vd), unit(Vq)
    if norm == "l2":
        return Vq @ Vd.T
    return np.array([[np.minimum(q, d).sum() for d in Vd] for q in Vq])


def structured_problem(rng: np.random.Generator, branching: int = 3, depth: int = 2, dim: int = 16,
                       n_db: int = 12, n_q: int = 4, ratio: float = 1000.0) -> dict:
    """Descriptors around k^L centres nested k per level: a level-l child sits 100 / ratio^l from its parent
    in a random direction, descriptors within ~100 / ratio^L of their centre, so hierarchical k-means
    (k-means++) recovers exactly these words, whatever it calls them. Every word is in some database image;
    each image holds 3-6 words, 1-4 descriptors of each. Word w's path is its base-k digits.

    Why ratio = 1000: k-means++ puts its next seed in an already seeded cluster with probability about
    (spread inside / distance between)^2, and Lloyd's iterations never undo that (two true words stay
    merged). At ratio 10 one seed in ~100 did so: the reference's single k-means++ run lost a word on 7 of
    2,000 cases (fairness seed 1208570590: words 1 and 2 merged, word 7 split in three); at 1000 it is
    ~1e-6 a choice, and 0 of 2,000 cases (cv2.kmeans in float32: 0 of 400). ratio=10 draws a readable
    2-D picture for the notebook."""
    k, L = branching, depth
    centres = np.zeros((1, dim))
    for level in range(L):
        off = rng.normal(size=(len(centres), k, dim))
        off *= 100.0 / ratio ** level / np.linalg.norm(off, axis=2, keepdims=True)
        centres = (centres[:, None, :] + off).reshape(-1, dim)
    n_words = k ** L

    def image():
        words = rng.choice(n_words, rng.integers(3, 7), replace=False)
        ws = np.repeat(words, rng.integers(1, 5, len(words)))
        return ws, centres[ws] + rng.normal(0, 100.0 / ratio ** L / np.sqrt(dim), (len(ws), dim))
    while True:
        db = [image() for _ in range(n_db)]
        if len(np.unique(np.concatenate([w for w, _ in db]))) == n_words:   # every word trained
            break
    qs = [image() for _ in range(n_q)]
    return {"db_descriptors": [d for _, d in db], "query_descriptors": [d for _, d in qs],
            "db_words": [w for w, _ in db], "query_words": [w for w, _ in qs], "n_words": n_words,
            "branching": k, "depth": L}


def _descend(x: np.ndarray, parents: np.ndarray, leaves: np.ndarray, k: int) -> tuple[int, int]:
    """(the tree's word: the nearest leaf under the nearest parent, the nearest leaf of all) for descriptor x."""
    a = int(np.argmin(((parents - x) ** 2).sum(1)))
    d2 = ((leaves - x) ** 2).sum(1)
    return a * k + int(np.argmin(d2[a * k:(a + 1) * k])), int(np.argmin(d2))


def boundary_problem(rng: np.random.Generator, branching: int = 3, n_q: int = 2, per_query: int = 3) -> dict:
    """structured_problem (depth 2) plus `n_q` queries that each hold `per_query` descriptors on a boundary between
    two branches: nearer branch a's centre than branch b's (or any other), but nearer one of b's leaves than any of
    a's, each by >= 0.01 (the centres are ~100 apart, a leaf ~0.1 from its parent), a's nearest leaf by >= 0.005. The tree descends
    into a; a flat vocabulary (every leaf compared) takes b's leaf. The centres are the means of the database
    descriptors of each branch and leaf: what k-means converges to on these exactly recovered clusters, so the
    tree's word is known. Returns the problem with its query lists extended and "margin" (the smallest)."""
    k = branching
    P = structured_problem(rng, branching=k, depth=2)
    X, w = np.concatenate(P["db_descriptors"]), np.concatenate(P["db_words"])
    leaves = np.array([X[w == c].mean(0) for c in range(k * k)])
    parents = np.array([X[w // k == a].mean(0) for a in range(k)])
    margin = np.inf
    for _ in range(n_q):
        descs, words = [], []
        while len(descs) < per_query:
            a, b = (int(i) for i in rng.choice(k, 2, replace=False))
            u = (parents[b] - parents[a]) / np.linalg.norm(parents[b] - parents[a])
            o = leaves[b * k + int(rng.integers(k))] - parents[b]   # the leaf of b to bring nearer
            z = o - (o @ u) * u
            x0 = (parents[a] + parents[b]) / 2 + 200.0 * z / np.linalg.norm(z)   # as far from a as from b

            def margins(t):
                """(d_b − d_a, min over a's leaves − min over b's leaves) at x0 + t u."""
                x = x0 + t * u
                la, lb = (np.min(np.linalg.norm(leaves[c * k:(c + 1) * k] - x, axis=1)) for c in (a, b))
                return np.linalg.norm(parents[b] - x) - np.linalg.norm(parents[a] - x), la - lb
            lo, hi = -1.0, 1.0                  # d_b − d_a falls as t grows, la − lb rises: bisect to equal them
            for _ in range(60):
                mid = (lo + hi) / 2
                d, m = margins(mid)
                lo, hi = (mid, hi) if d > m else (lo, mid)
            x = x0 + lo * u
            dp = np.sort(np.linalg.norm(parents - x, axis=1))
            dl = np.sort(np.linalg.norm(leaves[a * k:(a + 1) * k] - x, axis=1))
            # Every choice of the descent clear by >= 0.01 (the nearest parent) and 0.005 (a's nearest leaf): a
            # k-means that stops one update early (the reference's, within 1e-3) leaves centres ~1e-4 off the
            # means, cv2.kmeans in float32 ~1e-5; a's leaves nearly tied sent the reference elsewhere (1 of 300).
            m = min(min(margins(lo)), dp[1] - dp[0], 2 * (dl[1] - dl[0]))
            tree_word, flat_word = _descend(x, parents, leaves, k)
            if m < 0.01 or tree_word // k != a or flat_word // k != b:
                continue                        # not a clear boundary case (or a third branch is nearer)
            descs.append(x)
            words.append(tree_word)
            margin = min(margin, m)
        normal = rng.choice(k * k, 3, replace=False)
        P["query_descriptors"].append(np.vstack([np.array(descs)] + [X[w == c][:1] for c in normal]))
        P["query_words"].append(np.r_[words, normal])
    P["margin"] = float(margin)
    return P


# ------------------------------------------------------------------ the stand-in (OpenCV k-means)

def _cv_kmeans(X: np.ndarray, k: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    import cv2
    cv2.setRNGSeed(seed)
    crit = (cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_MAX_ITER, 30, 1e-4)
    _, labels, C = cv2.kmeans(np.asarray(X, np.float32), k, None, crit, 3, cv2.KMEANS_PP_CENTERS)
    return labels.ravel(), C.astype(float)


def cv_vocab_tree_retrieve(db_descriptors: list, query_descriptors: list, k: int = 5, branching: int = 6,
                           depth: int = 3, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Stand-in: the tree by cv2.kmeans (k-means++, 3 attempts) per node, descent, tf-idf, L1 scores."""
    nodes: list = []                     # node -> (centres (c, D), child node ids) or None for a leaf
    leaves: dict[int, int] = {}

    def build(X, level):
        me = len(nodes)
        nodes.append(None)
        if level == depth or len(X) <= branching:
            leaves[me] = len(leaves)
            return me
        labels, C = _cv_kmeans(X, branching, seed + me)
        nodes[me] = (C, [build(X[labels == c], level + 1) for c in range(branching)])
        return me

    build(np.concatenate(db_descriptors).astype(float), 0)

    def words(D):
        out = np.empty(len(D), int)
        for i, x in enumerate(np.asarray(D, float)):
            n = 0
            while nodes[n] is not None:
                C, kids = nodes[n]
                n = kids[int(np.argmin(((C - x) ** 2).sum(1)))]
            out[i] = leaves[n]
        return out
    S = tfidf_scores([words(D) for D in db_descriptors], [words(D) for D in query_descriptors], len(leaves))
    return np.argsort(-S, axis=1, kind="stable")[:, :k], S


# ------------------------------------------------------------------ judging

def _convert(out, case):
    Q, N, k = case.info["shape"]
    try:
        top, S = out
        top, S = np.asarray(top), np.asarray(S, float)
    except Exception:
        raise OutputError("expected (top, scores): top (Q, k) database indices, scores (Q, N)") from None
    if S.shape != (Q, N) or not np.isfinite(S).all():
        raise OutputError(f"scores must be a finite ({Q}, {N}) array, got {S.shape}")
    if top.shape != (Q, k) or not np.issubdtype(top.dtype, np.integer) or top.min() < 0 or top.max() >= N:
        raise OutputError(f"top must be ({Q}, {k}) integer indices into the {N} database images, got {top.shape}")
    return top, S


def _top_consistent(out, S_ref) -> float:
    """Largest gap between the k best scores and the scores of the returned top-k (ties are fine)."""
    top, S = out
    k = top.shape[1]
    best = -np.sort(-S, axis=1)[:, :k]
    return float(np.abs(best - np.take_along_axis(S, top, 1)).max())


def _place_cases(rng: np.random.Generator, n_places=10, views=4, k=5, branching=6, depth=3):
    P = place_problem(rng, n_places, views)
    args = (P["db_descriptors"], P["query_descriptors"], k, branching, depth)
    run = shared_run(lambda fn, a=args: fn(*a))
    bf = mean_ap(brute_force_scores(P["db_descriptors"], P["query_descriptors"]), P["db_labels"], P["query_labels"])
    info = dict(P, shape=(len(P["query_labels"]), len(P["db_labels"]), k), bf_map=bf)
    # mAP: within 0.2 of brute-force matching's on the same images and at least 0.6 (the tree quantises and
    # may lose some precision; on 30 draws the reference sat between 0.15 below and 0.25 above it).
    need = max(0.6, bf - 0.2)
    yield Case(f"{n_places} places: mAP >= {need:.2f} (brute force {bf:.2f})", args, P,
               lambda out, P: max(0.0, need - mean_ap(out[1], P["db_labels"], P["query_labels"])), 1e-9,
               "mAP short", convert=_convert, call=run, key="places-map", info=info, tags=("places",))
    # recall@k: every place found in the top k but at most one (the reference finds all on most draws).
    yield Case(f"{n_places} places: recall@{k} >= {1 - 1 / n_places:.2f}", args, P,
               lambda out, P: max(0.0, 1 - 1 / n_places - recall_at_k(out[0], P["db_labels"], P["query_labels"])),
               1e-9, "recall short", convert=_convert, call=run, key="places-recall", info=info, tags=("places",))


@cached
def _cases(rng: np.random.Generator):
    for i, (b, L) in enumerate([(3, 2), (2, 3)]):
        P = structured_problem(rng, branching=b, depth=L)
        S = tfidf_scores(P["db_words"], P["query_words"], P["n_words"])
        args = (P["db_descriptors"], P["query_descriptors"], 3, b, L)
        run = shared_run(lambda fn, a=args: fn(*a))
        info = dict(P, shape=(len(P["query_words"]), len(P["db_words"]), 3))
        # Exact words: the scores are sums of products of counts and logs, 1e-9 covers float64 rounding.
        yield Case(f"k = {b}, L = {L} structured words: tf-idf L1 scores", args, S,
                   lambda out, S: float(np.abs(out[1] - S).max()), 1e-9, "", convert=_convert, call=run,
                   key=f"words-{b}-{L}", info=info, tags=("words",))
        yield Case(f"k = {b}, L = {L} structured words: top-3 are the 3 best scores", args, S, _top_consistent,
                   1e-9, "", convert=_convert, call=run, key=f"top-{b}-{L}", info=info, tags=("words", "top"))
    yield from _place_cases(rng)
    # A tree quantises by descent, not by the nearest of all its leaves: descriptors on a boundary between two
    # branches (boundary_problem, margin >= 0.01 either way) tell the two apart. A flat vocabulary of k^L words with
    # brute-force assignment passed every case above (the words of the structured cases are the same either way).
    B = boundary_problem(rng)
    S = tfidf_scores(B["db_words"], B["query_words"], B["n_words"])
    args = (B["db_descriptors"], B["query_descriptors"], 3, B["branching"], B["depth"])
    info = dict(B, shape=(len(B["query_words"]), len(B["db_words"]), 3))
    yield Case(f"k = {B['branching']}, L = 2 words, queries on the boundaries between branches: tf-idf L1 scores "
               "of the tree's words", args, S, lambda out, S: float(np.abs(out[1] - S).max()), 1e-9, "",
               convert=_convert, call=shared_run(lambda fn, a=args: fn(*a)), key="descent", info=info,
               tags=("words", "descent"))


def _bug(**kw):
    return lambda c: tfidf_scores(c.info["db_words"], c.info["query_words"], c.info["n_words"], **kw)


def _flat(c):
    """Scores if the tree stopped after its first level: k words, each the parent of the true ones."""
    k, L = c.info["branching"], c.info["depth"]
    up = lambda ws: [np.asarray(w) // k ** (L - 1) for w in ws]
    return tfidf_scores(up(c.info["db_words"]), up(c.info["query_words"]), k)


def _scores_metric_hint(bug, text):
    h = like(bug, text)
    when = h.when
    h.when = lambda c, out: "words" in c.tags and "top" not in c.tags and when(c, out)
    return h


def _flat_words(c):
    """Scores if every descriptor took the nearest of all leaves (a flat vocabulary, no descent)."""
    k = c.info["branching"]
    X, w = np.concatenate(c.info["db_descriptors"]), np.concatenate(c.info["db_words"])
    leaves = np.array([X[w == j].mean(0) for j in range(k * k)])
    parents = np.array([X[w // k == a].mean(0) for a in range(k)])
    flat = [np.array([_descend(x, parents, leaves, k)[1] for x in np.asarray(D, float)]) for D in c.info["query_descriptors"]]
    return tfidf_scores(c.info["db_words"], flat, c.info["n_words"])


VOCAB_HINTS = [
    _scores_metric_hint(_flat_words, "these are the words of the nearest leaf of all (a flat vocabulary): a vocabulary "
                        "tree descends — the nearest centre at each level, then only that node's children — so a "
                        "descriptor on a boundary between two branches takes the leaf of the branch it is nearer to, "
                        "and quantising costs k·L comparisons, not k^L."),
    _scores_metric_hint(_bug(idf="descriptors"), "idf counts images: N_w is the number of database images that "
                        "contain word w (ln(N / N_w)), not the number of descriptors quantised to it."),
    _scores_metric_hint(_bug(norm="l2"), "L1, not L2: normalise each vector by ‖v‖₁ and score 1 − ½‖q̂ − d̂‖₁ "
                        "(Nistér & Stewénius found L1 clearly better than L2 for these histograms)."),
    _scores_metric_hint(_bug(idf="none"), "the words are not weighted: multiply each count by idf_w = ln(N / N_w), "
                        "so that a word every image has counts for nothing."),
    _scores_metric_hint(_flat, "only the first level's k words: split every node again, down to depth L (k^L leaves)."),
]
register(Exercise(
    id="10.6", title="A vocabulary tree with an inverted file", name="vocab_tree_retrieve", kind="code", points=4,
    cases=_cases, hints=VOCAB_HINTS, fallback=cv_vocab_tree_retrieve, timeout=30.0,
    arg_names=("db_descriptors", "query_descriptors", "k", "branching", "depth")))
