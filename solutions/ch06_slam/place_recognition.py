"""Chapter 6 reference: bag-of-words place recognition (6.14), from scratch with numpy."""
from __future__ import annotations

import numpy as np


def _sq_dist(X: np.ndarray, C: np.ndarray) -> np.ndarray:
    """(N, M) squared distances between the rows of X (N, D) and C (M, D)."""
    return np.maximum((X ** 2).sum(1)[:, None] - 2 * X @ C.T + (C ** 2).sum(1)[None, :], 0.0)


def kmeans(X: np.ndarray, k: int, seed: int = 0, iters: int = 30) -> np.ndarray:
    """Lloyd's k-means with k-means++ seeding (Arthur & Vassilvitskii 2007). X: (N, D) -> centres (k, D)."""
    rng = np.random.default_rng(seed)
    C = [X[rng.integers(len(X))]]
    d2 = _sq_dist(X, np.array(C))[:, 0]
    for _ in range(1, k):   # each new centre drawn with probability ∝ its squared distance to the chosen ones
        C.append(X[rng.choice(len(X), p=d2 / d2.sum())])
        d2 = np.minimum(d2, _sq_dist(X, C[-1][None])[:, 0])
    C = np.array(C)
    for _ in range(iters):
        label = np.argmin(_sq_dist(X, C), axis=1)
        counts = np.bincount(label, minlength=k)
        sums = np.zeros_like(C)
        np.add.at(sums, label, X)
        new = np.where(counts[:, None] > 0, sums / np.maximum(counts, 1)[:, None], C)   # empty cluster: keep
        if np.allclose(new, C):
            break
        C = new
    return C


def bow_vectors(descs: list, V: np.ndarray, idf: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """tf-idf vectors, L1-normalised, of images given as descriptor arrays. Returns (vectors (n, W), idf (W,));
    idf = log(N / N_w) over these images unless given."""
    H = np.array([np.bincount(np.argmin(_sq_dist(d, V), axis=1), minlength=len(V)) for d in descs], float)
    if idf is None:
        n_w = (H > 0).sum(0)
        idf = np.log(len(descs) / np.maximum(n_w, 1)) * (n_w > 0)
    v = H / np.maximum(H.sum(1, keepdims=True), 1) * idf
    norm = v.sum(1, keepdims=True)
    return v / np.where(norm > 0, norm, 1), idf


def bow_scores(db: list, queries: list, vocabulary, top_k: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 6.14: DBoW2-style retrieval of each query among the database images.

    db, queries: lists of (n_i, D) descriptor arrays, one per image. vocabulary: the words (W, D), or a
    word count W, then trained by k-means on all database descriptors (seed: its initialisation).
    Words by nearest centre; v = tf·idf, tf = n_iw / n_i, idf = log(N / N_w) over the N database images
    (N_w: images containing w); s(a, b) = 1 − ½‖a/‖a‖₁ − b/‖b‖₁‖₁.
    Returns S (Q, N) scores and top (Q, top_k) database indices, best first."""
    V = kmeans(np.vstack(db), int(vocabulary), seed) if np.ndim(vocabulary) == 0 else np.asarray(vocabulary, float)
    B, idf = bow_vectors(db, V)
    A, _ = bow_vectors(queries, V, idf)
    S = 1 - 0.5 * np.abs(A[:, None, :] - B[None, :, :]).sum(2)
    return S, np.argsort(-S, axis=1, kind="stable")[:, :top_k]
