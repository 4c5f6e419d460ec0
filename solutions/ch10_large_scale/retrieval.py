"""Exercise 10.6's reference: a vocabulary tree (hierarchical k-means++), tree descent, tf-idf,
L1-normalised scores computed through an inverted file (Nistér & Stewénius 2006; Sivic & Zisserman 2003)."""
from __future__ import annotations

import numpy as np


def kmeans(X: np.ndarray, k: int, rng: np.random.Generator, iters: int = 30) -> tuple[np.ndarray, np.ndarray]:
    """Lloyd's k-means with k-means++ seeding. X: (n, D), n >= k -> (labels (n,), centres (k, D))."""
    C = [X[rng.integers(len(X))]]
    d2 = ((X - C[0]) ** 2).sum(1)
    for _ in range(1, k):                        # k-means++: the next seed with probability ∝ D(x)²
        p = d2 / d2.sum() if d2.sum() > 0 else np.full(len(X), 1 / len(X))
        C.append(X[rng.choice(len(X), p=p)])
        d2 = np.minimum(d2, ((X - C[-1]) ** 2).sum(1))
    C = np.array(C, float)
    for _ in range(iters):
        D2 = (X ** 2).sum(1)[:, None] - 2 * X @ C.T + (C ** 2).sum(1)[None]
        labels = np.argmin(D2, 1)
        newC = np.array([X[labels == c].mean(0) if np.any(labels == c) else C[c] for c in range(k)])
        if np.allclose(newC, C):
            break
        C = newC
    return labels, C


class _Tree:
    """Node n: centres[n] (k, D) and children[n] (k node ids), or a leaf with a word id."""

    def __init__(self, X: np.ndarray, branching: int, depth: int, seed: int):
        self.k, self.centres, self.children, self.word = branching, {}, {}, {}
        self.rng = np.random.default_rng(seed)
        self._build(X, 0)

    def _build(self, X: np.ndarray, level: int) -> int:
        node = len(self.centres) + len(self.word)
        if level == self.depth or len(X) <= self.k:
            self.word[node] = len(self.word)
            return node
        self.centres[node] = None                          # reserve the id before the children take theirs
        labels, C = kmeans(X, self.k, self.rng)
        self.centres[node] = C
        self.children[node] = [self._build(X[labels == c], level + 1) for c in range(self.k)]
        return node

    def quantise(self, D: np.ndarray) -> np.ndarray:
        """Each descriptor's word by descending the tree: k distances per level. D: (n, D) -> (n,)."""
        out = np.empty(len(D), int)
        for i, x in enumerate(D):
            node = 0
            while node in self.centres:
                node = self.children[node][int(np.argmin(((self.centres[node] - x) ** 2).sum(1)))]
            out[i] = self.word[node]
        return out


def vocab_tree_retrieve(db_descriptors: list, query_descriptors: list, k: int = 5, branching: int = 6,
                        depth: int = 3, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 10.6: the top-k database images for each query by a vocabulary tree.

    db_descriptors: N arrays (n_i, D); query_descriptors: Q arrays (m_j, D). The tree (branching k,
    depth L, k^L leaves at most) is trained on all database descriptors. Weights v_w = n_w ln(N / N_w),
    v̂ = v / ‖v‖₁, score = 1 − ½‖q̂ − d̂‖₁ = Σ_w min(q̂_w, d̂_w), accumulated over the inverted file of
    each query word. Returns (top: (Q, k) indices, best first; scores: (Q, N))."""
    tree = _Tree.__new__(_Tree)
    tree.depth = depth
    tree.__init__(np.concatenate(db_descriptors).astype(float), branching, depth, seed)
    n_words, N = len(tree.word), len(db_descriptors)
    db_counts = [np.bincount(tree.quantise(np.asarray(D, float)), minlength=n_words) for D in db_descriptors]
    Nw = np.sum([c > 0 for c in db_counts], 0)
    idf = np.where(Nw > 0, np.log(N / np.maximum(Nw, 1)), 0.0)

    def unit(counts):
        v = counts * idf
        return v / v.sum() if v.sum() > 0 else v
    inverted: dict[int, list[tuple[int, float]]] = {}          # word -> [(image, d̂_w)]
    for i, c in enumerate(db_counts):
        d = unit(c)
        for w in np.flatnonzero(d):
            inverted.setdefault(int(w), []).append((i, float(d[w])))
    S = np.zeros((len(query_descriptors), N))
    for j, D in enumerate(query_descriptors):
        q = unit(np.bincount(tree.quantise(np.asarray(D, float)), minlength=n_words)) if len(D) else np.zeros(n_words)
        for w in np.flatnonzero(q):                              # only images sharing a word are touched
            for i, dw in inverted.get(int(w), ()):
                S[j, i] += min(q[w], dw)
    return np.argsort(-S, axis=1, kind="stable")[:, :k], S
