"""Chapter 6, section 2: 6.8 `read_g2o`, a g2o pose graph with its information matrices.

Oracle: gtsam.readG2o (which also permutes SE(3) information to its rotation-first order) on the same
text. Files: synthetic SE(2) graphs in g2o's text (vertex ids not contiguous, listed out of order, full
information matrices), synthetic SE(3) graphs written by gtsam.writeG2o, and the real intel and
parking-garage files. g2o stores the upper triangle of each information matrix row by row,
I11 I12 ... I1k I22 ... Ikk, in its own error order: (x, y, theta) for SE(2), (t, q_xyz) for SE(3).
"""
from __future__ import annotations

import os
import tempfile

import numpy as np

from graders import datasets
from graders.engine import Case, Exercise, OutputError, like, raised, register

from .manifold import gt_exp, random_poses
from .posegraphs import POSEGRAPH_FILES, gtsam_pose, make_graph

KEYS = ("ids", "T", "edges", "Z", "info")


def gt_read_g2o(path) -> dict:
    """gtsam.readG2o as read_g2o's dict (the oracle and the library-backed 6.8)."""
    import gtsam
    text = open(path).read()
    is3 = "VERTEX_SE3:QUAT" in text
    graph, values = gtsam.readG2o(str(path), is3)
    ids = np.array(sorted(values.keys()))
    index = {int(v): n for n, v in enumerate(ids)}
    get = values.atPose3 if is3 else values.atPose2
    edges, Z, info = [], [], []
    for k in range(graph.size()):
        f = graph.at(k)
        a, b = f.keys()
        edges.append([index[a], index[b]])
        Z.append(f.measured().matrix())
        R = f.noiseModel().R()
        info.append(R.T @ R)
    return {"ids": ids, "T": np.array([get(int(i)).matrix() for i in ids]), "edges": np.array(edges, int),
            "Z": np.array(Z), "info": np.array(info)}


def _se2_text(rng) -> str:
    """A synthetic SE(2) graph as g2o text: ids 3 + 7k listed out of order, full information matrices."""
    g = make_graph(rng, dim=2, n=40, n_loops=6)
    n, m = len(g["T"]), len(g["edges"])
    ids = 3 + 7 * np.arange(n)
    A = rng.normal(0, 1, (m, 3, 3))
    info = A @ np.swapaxes(A, 1, 2) + 3 * np.eye(3)              # symmetric positive definite, not diagonal
    iu = np.triu_indices(3)

    def xyt(P):
        return [P[0, 2], P[1, 2], np.arctan2(P[1, 0], P[0, 0])]

    lines = [f"VERTEX_SE2 {ids[i]} " + " ".join(f"{v:.17g}" for v in xyt(g["T"][i])) for i in rng.permutation(n)]
    for (a, b), Z, I in zip(g["edges"], g["Z"], info):
        lines.append(f"EDGE_SE2 {ids[a]} {ids[b]} " + " ".join(f"{v:.17g}" for v in xyt(Z) + list(I[iu])))
    return "\n".join(lines) + "\n"


def _se3_text(rng) -> str:
    """A synthetic SE(3) graph written by gtsam.writeG2o (full information, rotation/translation coupled)."""
    import gtsam
    n = 30
    T = random_poses(rng, n, 3)
    edges = np.r_[np.c_[np.arange(n - 1), np.arange(1, n)], [rng.choice(n, 2, replace=False) for _ in range(8)]]
    graph, values = gtsam.NonlinearFactorGraph(), gtsam.Values()
    for i, P in enumerate(T):
        values.insert(i, gtsam_pose(P))
    for a, b in edges:
        A = rng.normal(0, 1, (6, 6))
        model = gtsam.noiseModel.Gaussian.Information(A @ A.T + 2 * np.eye(6))
        Z = np.linalg.inv(T[a]) @ T[b] @ gt_exp(rng.normal(0, 0.1, 6))[0]
        graph.add(gtsam.BetweenFactorPose3(int(a), int(b), gtsam_pose(Z), model))
    with tempfile.TemporaryDirectory(prefix="cv3d_ch06_") as folder:
        path = os.path.join(folder, "graph.g2o")
        gtsam.writeG2o(graph, values, path)
        return open(path).read()


def _from_temporary_file(text: str):
    """How 6.8 calls the learner: with the path of a g2o file that exists only during the call."""
    def call(fn):
        with tempfile.TemporaryDirectory(prefix="cv3d_ch06_") as folder:
            path = os.path.join(folder, "graph.g2o")
            with open(path, "w") as f:
                f.write(text)
            return fn(path)
    return call


def _expected_from_text(text: str) -> dict:
    with tempfile.TemporaryDirectory(prefix="cv3d_ch06_") as folder:
        path = os.path.join(folder, "graph.g2o")
        with open(path, "w") as f:
            f.write(text)
        return gt_read_g2o(path)


def _convert(out, case):
    exp = case.expected
    if not isinstance(out, dict) or any(k not in out for k in KEYS):
        raise OutputError(f"expected a dict with keys {', '.join(KEYS)}")
    got = {}
    for k in KEYS:
        try:
            a = np.asarray(out[k], float)
        except (TypeError, ValueError):
            raise OutputError(f'"{k}": expected a numeric array') from None
        if a.shape != exp[k].shape:
            raise OutputError(f'"{k}": shape {a.shape}, expected {exp[k].shape}')
        if not np.isfinite(a).all():
            raise OutputError(f'"{k}": non-finite values')
        got[k] = a
    return got


def _metric(out, exp) -> float:
    """The largest error over the fields: ids and edges exactly (any mismatch counts 1), poses and
    measurements as matrices (a quaternion and its negative give the same matrix), information relative
    to its largest entry."""
    wrong_ids = float(np.any(out["ids"] != exp["ids"]) or np.any(out["edges"] != exp["edges"]))
    pose = max(np.abs(out["T"] - exp["T"]).max(), np.abs(out["Z"] - exp["Z"]).max())
    info = (np.abs(out["info"] - exp["info"]).max(axis=(1, 2)) / np.abs(exp["info"]).max(axis=(1, 2))).max()
    return float(max(wrong_ids, pose, info))


def _info_lower(case):
    """The information read as the lower triangle row by row (column-major upper): a transposed fill order."""
    exp = case.expected
    k = exp["info"].shape[-1]
    iu, il = np.triu_indices(k), np.tril_indices(k)
    out = dict(exp)
    vals = exp["info"][:, iu[0], iu[1]]
    info = np.zeros_like(exp["info"])
    info[:, il[0], il[1]] = vals
    info[:, il[1], il[0]] = vals
    out["info"] = info
    return out


def _info_g2o_order(case):
    exp = case.expected
    if exp["info"].shape[-1] != 6:
        return {k: np.full_like(np.asarray(v, float), np.nan) for k, v in exp.items()}
    order = [3, 4, 5, 0, 1, 2]
    return dict(exp, info=exp["info"][:, order][:, :, order])


HINTS = [
    like(_info_lower, "the information matrices are filled in the wrong order: g2o writes the upper triangle row "
                      "by row (I11 I12 ... I1k I22 ... Ikk)."),
    like(_info_g2o_order, "SE(3) information is in g2o's order (translation, rotation); this chapter's residual "
                          "is (omega, v), rotation first: permute rows and columns, as GTSAM's readG2o does."),
    raised(r"IndexError|KeyError", "vertex ids are names, not row numbers: they need not start at 0, be "
                                   "contiguous or come in order. Sort the ids and map each to its row."),
]


# 1e-9: the synthetic files hold 17 significant digits (gtsam.writeG2o writes ~10-16; the real files 6);
# parsing either way is exact to ~1e-15, and a quaternion -> matrix conversion to ~1e-15.
def cases_read_g2o(rng):
    yield Case("SE(2): ids out of order and not contiguous, full information", ("graph.g2o",),
               _expected_from_text(t := _se2_text(rng)), _metric, 1e-9, "max", convert=_convert,
               call=_from_temporary_file(t), key="synthetic-se2")
    yield Case("SE(3): written by gtsam.writeG2o, full information", ("graph.g2o",),
               _expected_from_text(t3 := _se3_text(rng)), _metric, 1e-9, "max", convert=_convert,
               call=_from_temporary_file(t3), key="synthetic-se3")
    if datasets.available("posegraph"):
        for name, what in (("intel", "1,728 poses, 2,512 edges"), ("garage", "1,661 poses, 6,275 edges")):
            path = str(datasets.path("posegraph", POSEGRAPH_FILES[name]))
            yield Case(f"real: {POSEGRAPH_FILES[name]} ({what})", (path,), _real(name), _metric, 1e-9, "max",
                       convert=_convert, key=f"real-{name}", tags=("real",))


_REAL: dict = {}


def _real(name: str) -> dict:
    if name not in _REAL:
        _REAL[name] = gt_read_g2o(datasets.path("posegraph", POSEGRAPH_FILES[name]))
    return _REAL[name]


register(Exercise(
    id="6.8",
    title="Read a g2o pose graph",
    name="read_g2o",
    kind="code",
    points=2,
    cases=cases_read_g2o,
    hints=HINTS,
    fallback=gt_read_g2o,
    arg_names=("path",),
))
