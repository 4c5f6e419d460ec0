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
        """Each descriptor's word by descending the tree: k distances per level. D: (n, D) -> (n,).
        All descriptors descend together, one level at a time: the Python loop runs over the tree's
        nodes (1 + k + k² ...), not over the descriptors."""
        node = np.zeros(len(D), int)                               # every descriptor starts at the root
        for _ in range(self.depth):
            for n in np.unique(node):
                if n not in self.centres:                          # a leaf above the last level
                    continue
                here = node == n
                d2 = ((D[here, None, :] - self.centres[n][None]) ** 2).sum(2)    # (m, k)
                node[here] = np.asarray(self.children[n])[np.argmin(d2, 1)]
        return np.array([self.word[n] for n in node], int)


def build_index(db_descriptors: list, branching: int = 6, depth: int = 3, seed: int = 0) -> dict:
    """The offline half: the tree trained on all database descriptors, the idf weights and the inverted
    file word -> (images (m,), d̂_w (m,)). db_descriptors: N arrays (n_i, D)."""
    tree = _Tree.__new__(_Tree)
    tree.depth = depth
    tree.__init__(np.concatenate(db_descriptors).astype(float), branching, depth, seed)
    n_words, N = len(tree.word), len(db_descriptors)
    db_counts = [np.bincount(tree.quantise(np.asarray(D, float)), minlength=n_words) for D in db_descriptors]
    Nw = np.sum([c > 0 for c in db_counts], 0)
    idf = np.where(Nw > 0, np.log(N / np.maximum(Nw, 1)), 0.0)
    Vd = np.array([_unit(c * idf) for c in db_counts])             # (N, words), rows sum to 1
    inverted = {int(w): (np.flatnonzero(Vd[:, w]), Vd[Vd[:, w] > 0, w]) for w in range(n_words)}
    return {"tree": tree, "idf": idf, "inverted": inverted, "N": N, "n_words": n_words}


def _unit(v: np.ndarray) -> np.ndarray:
    return v / v.sum() if v.sum() > 0 else v.astype(float)


def query_scores(index: dict, D: np.ndarray) -> np.ndarray:
    """The online half: one query's scores Σ_w min(q̂_w, d̂_w) against every database image, (N,),
    accumulated over the inverted-file lists of the query's own words (images sharing none stay 0)."""
    S = np.zeros(index["N"])
    if not len(D):
        return S
    q = _unit(np.bincount(index["tree"].quantise(np.asarray(D, float)), minlength=index["n_words"]) * index["idf"])
    for w in np.flatnonzero(q):
        images, dw = index["inverted"][int(w)]
        S[images] += np.minimum(q[w], dw)
    return S


def vocab_tree_retrieve(db_descriptors: list, query_descriptors: list, k: int = 5, branching: int = 6,
                        depth: int = 3, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Exercise 10.6: the top-k database images for each query by a vocabulary tree.

    db_descriptors: N arrays (n_i, D); query_descriptors: Q arrays (m_j, D). The tree (branching k,
    depth L, k^L leaves at most) is trained on all database descriptors. Weights v_w = n_w ln(N / N_w),
    v̂ = v / ‖v‖₁, score = 1 − ½‖q̂ − d̂‖₁ = Σ_w min(q̂_w, d̂_w), accumulated over the inverted file of
    each query word. Returns (top: (Q, k) indices, best first; scores: (Q, N))."""
    index = build_index(db_descriptors, branching, depth, seed)
    S = np.array([query_scores(index, D) for D in query_descriptors]).reshape(len(query_descriptors), index["N"])
    return np.argsort(-S, axis=1, kind="stable")[:, :k], S
