"""3.11 brute-force matching with the ratio test and mutual nearest neighbours: cv2.BFMatcher as the
oracle, query by query (queries that rounding could tip either way are skipped), hidden cases, hints."""
from __future__ import annotations

import numpy as np

from graders.core.engine import Case, Exercise, Hint, OutputError, register
from graders.core.memo import cached
from ..oracles.features import cv_match


# ============================================================ 3.11 matching ====

def _descriptor_sets(rng: np.random.Generator, n, m, d, noise=0.25, shared=0.6):
    """D2 holds noisy copies of a fraction of D1's rows (true matches) among distractors."""
    D1 = rng.normal(size=(n, d))
    D2 = rng.normal(size=(m, d))
    k = int(shared * min(n, m))
    src, dst = rng.permutation(n)[:k], rng.permutation(m)[:k]
    D2[dst] = D1[src] + noise * rng.uniform(0.2, 3.0, (k, 1)) * rng.normal(size=(k, d))
    return D1.astype(np.float32).astype(float), D2.astype(np.float32).astype(float)


def _ambiguous(D1, D2, ratio):
    """Queries whose answer depends on rounding: best two nearly tied, or the ratio on its threshold."""
    d = np.sqrt(np.maximum(np.sum(D1 ** 2, 1)[:, None] + np.sum(D2 ** 2, 1)[None] - 2 * D1 @ D2.T, 0))
    s = np.sort(d, axis=1)
    amb = s[:, 1] - s[:, 0] < 1e-4 * s[:, 1]
    if ratio is not None:
        amb |= np.abs(s[:, 0] / s[:, 1] - ratio) < 1e-4
    return amb


def _match_convert(out, case):
    arr = np.asarray(out)
    if arr.size == 0:
        return np.zeros((0, 2), np.int64)
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise OutputError(f"expected (K, 2) rows (i, j), got shape {arr.shape}")
    if not np.issubdtype(arr.dtype, np.integer):
        if not np.all(arr == np.rint(arr)):
            raise OutputError("indices must be integers")
    return arr.astype(np.int64)


def _match_metric(out, exp):
    """Number of (non-ambiguous) queries on which the matches differ from cv2.BFMatcher's."""
    ok = ~exp["ambiguous"]
    mine = {int(i): int(j) for i, j in out}
    if len(mine) != len(out):
        raise OutputError("a query index appears twice")
    ref = {int(i): int(j) for i, j in exp["pairs"]}
    return float(sum(1 for i in np.nonzero(ok)[0] if mine.get(i) != ref.get(i)))


@cached    # the same draw for every grade of a seed: its oracle runs once per process
def cases_match(rng: np.random.Generator) -> list[Case]:
    out = []
    for key, name, n, m, d, ratio, mutual in [
            ("ratio", "300 × 400 × 64, ratio 0.8", 300, 400, 64, 0.8, False),
            ("ratio-mutual", "250 × 200 × 128, ratio 0.6, mutual", 250, 200, 128, 0.6, True),
            ("mutual", "200 × 300 × 32, no ratio test, mutual", 200, 300, 32, None, True),
            ("speed", "2,000 × 2,000 × 128, ratio 0.8 (speed: 10 s)", 2000, 2000, 128, 0.8, False)]:
        D1, D2 = _descriptor_sets(rng, n, m, d)
        exp = {"pairs": cv_match(D1, D2, ratio, mutual), "ambiguous": _ambiguous(D1, D2, ratio)}
        # 0: nearest neighbours are exact; rounding-sensitive queries (ties within 1e-4) are excluded.
        out.append(Case(name, (D1, D2, ratio, mutual), exp, _match_metric, 0.0, "queries differ",
                        convert=_match_convert, info={"ratio": ratio, "mutual": mutual}, key=key))
    return out


def _match_bug(**kw):
    def bug(c):
        D1, D2, ratio, mutual = c.args
        args = {"ratio": ratio, "mutual": mutual} | kw
        if "square" in args:
            args.pop("square")
            if ratio is None:
                raise ValueError
            args["ratio"] = np.sqrt(ratio)  # d1² < r d2²  <=>  d1 < sqrt(r) d2
        if args.pop("inverted", False):
            if ratio is None:
                raise ValueError
            return _inverted(D1, D2, ratio)
        return cv_match(D1, D2, **args)
    return bug


def _inverted(D1, D2, ratio):
    d = np.sqrt(np.maximum(np.sum(D1 ** 2, 1)[:, None] + np.sum(D2 ** 2, 1)[None] - 2 * D1 @ D2.T, 0))
    s = np.sort(d, 1)
    keep = s[:, 0] / s[:, 1] > ratio
    return np.c_[np.nonzero(keep)[0], d.argmin(1)[keep]]


def _match_like(bug, text):
    def when(case, out):
        try:
            return _match_metric(out, {"pairs": bug(case), "ambiguous": case.expected["ambiguous"]}) == 0
        except Exception:
            return False
    return Hint(text, when)


MATCH_HINTS = [
    _match_like(_match_bug(square=True), "the ratio test compares squared distances with the ratio: Lowe's test "
                "is d1 < ratio · d2 on distances (or d1² < ratio² · d2²)."),
    _match_like(_match_bug(inverted=True), "the ratio test is inverted: keep a match when d1 / d2 is *below* the ratio."),
    _match_like(_match_bug(mutual=False), "mutual=True: also require that i is the nearest neighbour of j in D1."),
    Hint("rows should be (i, j): i indexes D1 (the query), j indexes D2.",
         lambda c, out: _match_metric(out[:, ::-1], c.expected) == 0 if len(out) else False),
]


register(
    Exercise(id="3.11", title="Brute-force matching: ratio test and mutual nearest neighbours", name="match_descriptors",
             kind="code", points=3, cases=cases_match, hints=MATCH_HINTS, fallback=cv_match,
             arg_names=("D1", "D2", "ratio", "mutual")),
)
