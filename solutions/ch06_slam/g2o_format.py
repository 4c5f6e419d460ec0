"""The g2o text format (exercises 6.8 and 6.27): read every form a public pose graph comes in, write one any g2o
reader reads back.

Read (tags, one element per line; ids are integers, values numbers):
    VERTEX_SE2 id x y theta                     EDGE_SE2 i j x y theta I11 I12 I13 I22 I23 I33
    VERTEX_SE3:QUAT id x y z qx qy qz qw        EDGE_SE3:QUAT i j x y z qx qy qz qw I11 .. I16 I22 .. I66
Skipped: blank lines, comments (a first token starting with "#"), FIX lines (g2o's gauge hint; the optimisers here
always hold the first pose) and every other tag (landmarks, PARAMS_*, other edge types), the last with one warning
naming the tags, since the graph returned is then the pose graph alone.
"""
from __future__ import annotations

import warnings
from collections import Counter
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

# tag -> (dimension d, number of ids, number of pose values, number of information values)
LAYOUT = {"VERTEX_SE2": (2, 1, 3, 0), "EDGE_SE2": (2, 2, 3, 6),
          "VERTEX_SE3:QUAT": (3, 1, 7, 0), "EDGE_SE3:QUAT": (3, 2, 7, 21)}
SE3_INFO_ORDER = [3, 4, 5, 0, 1, 2]     # g2o's (t, R) blocks <-> the residual's (omega, v); its own inverse


def _pose_from_g2o(values: np.ndarray, d: int) -> np.ndarray:
    """g2o's (x, y, theta) or (x, y, z, qx, qy, qz, qw) rows -> (N, d+1, d+1)."""
    T = np.zeros((len(values), d + 1, d + 1))
    T[:, d, d] = 1.0
    if d == 2:
        c, s = np.cos(values[:, 2]), np.sin(values[:, 2])
        T[:, 0, 0], T[:, 0, 1], T[:, 1, 0], T[:, 1, 1] = c, -s, s, c
        T[:, :2, 2] = values[:, :2]
    else:
        T[:, :3, :3] = Rotation.from_quat(values[:, 3:7]).as_matrix()  # scipy's order is g2o's: (qx, qy, qz, qw)
        T[:, :3, 3] = values[:, :3]
    return T


def _info_from_upper(upper: np.ndarray, k: int) -> np.ndarray:
    """g2o stores the upper triangle row by row: I11 I12 .. I1k I22 .. Ikk. (M, k(k+1)/2) -> (M, k, k)."""
    iu = np.triu_indices(k)
    info = np.zeros((len(upper), k, k))
    info[:, iu[0], iu[1]] = upper
    info[:, iu[1], iu[0]] = upper
    return info


def _parse_lines(text: str, path) -> tuple[int, dict, list, list]:
    """The pose lines of a g2o text -> (d, {id: values}, [(i, j)], [values]); the rule for every other line is the
    module docstring's. Malformed pose lines, mixed SE(2)/SE(3) and repeated vertex ids raise ValueError."""
    verts, pairs, rows, dims, skipped = {}, [], [], set(), Counter()
    for n, line in enumerate(text.splitlines(), 1):
        tok = line.split()
        if not tok or tok[0].startswith("#") or tok[0] == "FIX":
            continue
        if tok[0] not in LAYOUT:
            skipped[tok[0]] += 1
            continue
        d, n_ids, nz, ni = LAYOUT[tok[0]]
        if len(tok) != 1 + n_ids + nz + ni:
            raise ValueError(f"{path}:{n}: {tok[0]} needs {n_ids} ids and {nz + ni} values, got {len(tok) - 1} tokens")
        try:
            ij, values = [int(t) for t in tok[1:1 + n_ids]], [float(t) for t in tok[1 + n_ids:]]
        except ValueError:
            raise ValueError(f"{path}:{n}: ids must be integers and values numbers: {line.strip()[:80]!r}") from None
        dims.add(d)
        if n_ids == 1:
            if ij[0] in verts:
                raise ValueError(f"{path}:{n}: vertex {ij[0]} defined twice (g2o and GTSAM refuse this too)")
            verts[ij[0]] = values
        else:
            pairs.append(ij)
            rows.append(values)
    if len(dims) != 1:
        raise ValueError(f"{path}: " + ("SE(2) and SE(3) elements mixed in one file" if dims else
                                        f"no VERTEX_SE2/EDGE_SE2 or VERTEX_SE3:QUAT/EDGE_SE3:QUAT lines"))
    if skipped:
        warnings.warn(f"{path}: skipped lines that are not SE(2)/SE(3) poses or pose edges: "
                      + ", ".join(f"{t} x{c}" for t, c in skipped.items()), stacklevel=3)
    return dims.pop(), verts, pairs, rows


def chain_odometry(ids: np.ndarray, known: dict, pairs: np.ndarray, Z: np.ndarray) -> tuple[np.ndarray, list]:
    """Start values for vertices without a VERTEX line, by composing measurements from vertices that have one.

    ids (N,) sorted, known {id: (d+1, d+1)} (may be empty: then the smallest id is the identity), pairs (M, 2) edge
    ids, Z (M, d+1, d+1) -> T (N, d+1, d+1) and the ids reached only through a non-odometry edge. The rule, in
    order: (1) the odometry edge to the neighbouring id (T_next = T_prev Z, or T_prev Z^-1 for an edge listed
    the other way), up the ids from the placed vertices, then down; (2) where the odometry is missing, the first
    edge in file order that joins a placed vertex to an unplaced one, then odometry again from there; (3) a vertex joined to no placed one by any edge is a separate graph
    with its own gauge: ValueError. GTSAM's load2D (gtsam/slam/dataset.cpp) does (1)-(2) in file order - each
    edge's unknown second vertex becomes T_first Z, an unknown first one the identity - and its load3D places no
    vertex at all; on files that list the odometry first, (1) and GTSAM's 2D rule agree."""
    ids = [int(v) for v in ids]
    known = {int(v): P for v, P in known.items()} or {ids[0]: np.eye(Z.shape[-1])}
    odometry = {}
    for m, (a, b) in enumerate(pairs):
        odometry.setdefault((int(a), int(b)), (m, False))
        odometry.setdefault((int(b), int(a)), (m, True))
    via_other = []
    while len(known) < len(ids):
        for near, v in [*zip(ids[:-1], ids[1:]), *zip(ids[:0:-1], ids[-2::-1])]:   # (1): up, then down the ids
            if v not in known and near in known and (near, v) in odometry:
                m, flipped = odometry[(near, v)]
                known[v] = known[near] @ (np.linalg.inv(Z[m]) if flipped else Z[m])
        if len(known) == len(ids):
            break
        for m, (a, b) in enumerate(pairs):                             # (2): one vertex through another edge
            a, b = int(a), int(b)
            if (a in known) != (b in known):
                v = b if a in known else a
                known[v] = known[a] @ Z[m] if a in known else known[b] @ np.linalg.inv(Z[m])
                via_other.append(v)
                break
        else:                                                          # (3)
            lost = [v for v in ids if v not in known]
            raise ValueError(f"vertices {lost[:5]}{' ...' if len(lost) > 5 else ''} ({len(lost)}) have no VERTEX "
                             "line and no edge to a placed vertex: the graph has more than one connected part, "
                             "each with its own gauge; split the file or add the missing odometry")
    return np.array([known[v] for v in ids]), via_other


def read_g2o(path: str | Path) -> dict:
    """Exercise 6.8: read a g2o pose graph, SE(2) (VERTEX_SE2/EDGE_SE2) or SE(3) (VERTEX_SE3:QUAT/EDGE_SE3:QUAT),
    with or without VERTEX lines.

    Returns {"ids": (N,) vertex ids in increasing order, "T": (N, d+1, d+1), "edges": (M, 2) indices into
    T (rows of "ids"), "Z": (M, d+1, d+1), "info": (M, k, k) in the residual's order}. For SE(3), g2o's
    information is ordered (translation, rotation); it is permuted to (rotation, translation), as GTSAM does.
    The vertices are every id of a VERTEX line or an edge; one without a VERTEX line starts where
    `chain_odometry` puts it (a warning names those reached only through a loop closure). Lines that are not
    pose elements are skipped by the module docstring's rule. The information is returned as the file holds it;
    `pose_graph.check_information` judges it (the optimisers refuse a matrix that is not positive semi-definite).
    """
    d, verts, pairs, rows = _parse_lines(Path(path).read_text(), path)
    nz, k = (3, 3) if d == 2 else (7, 6)
    E = np.array(rows, float).reshape(-1, nz + k * (k + 1) // 2)
    pairs = np.array(pairs, int).reshape(-1, 2)
    ids = np.array(sorted(set(verts) | set(pairs.ravel().tolist())), int)
    Z = _pose_from_g2o(E[:, :nz], d)
    known = dict(zip(verts, _pose_from_g2o(np.array(list(verts.values()), float).reshape(-1, nz), d)))
    T, via_other = chain_odometry(ids, known, pairs, Z) if len(known) < len(ids) else (
        np.array([known[int(v)] for v in ids]), [])
    if via_other:
        warnings.warn(f"{path}: no odometry edge to vertices {via_other[:5]}{' ...' if len(via_other) > 5 else ''}: "
                      "started them through another edge (a loop closure)", stacklevel=2)
    info = _info_from_upper(E[:, nz:], k)
    if d == 3:
        info = info[:, SE3_INFO_ORDER][:, :, SE3_INFO_ORDER]
    return {"ids": ids, "T": T, "edges": np.searchsorted(ids, pairs), "Z": Z, "info": info}


def write_g2o(path: str | Path, graph: dict) -> None:
    """Exercise 6.27: write `graph` (read_g2o's dict) as g2o text.

    Vertex n is written under its id graph["ids"][n] (0..N-1 if absent), each edge as the ids of its rows;
    SE(3) quaternions as qx qy qz qw; information back to g2o's order (translation first for SE(3)), upper
    triangle row by row; every number with repr, so the round trip loses nothing.
    """
    T, ids = graph["T"], graph.get("ids", np.arange(len(graph["T"])))
    d = T.shape[-1] - 1

    def pose(P):
        if d == 2:
            return [P[0, 2], P[1, 2], np.arctan2(P[1, 0], P[0, 0])]
        return list(P[:3, 3]) + list(Rotation.from_matrix(P[:3, :3]).as_quat())

    info = graph["info"]
    if d == 3:
        info = info[:, SE3_INFO_ORDER][:, :, SE3_INFO_ORDER]
    iu = np.triu_indices(info.shape[-1])
    tag = ("VERTEX_SE2", "EDGE_SE2") if d == 2 else ("VERTEX_SE3:QUAT", "EDGE_SE3:QUAT")
    lines = [" ".join([tag[0], str(int(i))] + [repr(float(v)) for v in pose(P)]) for i, P in zip(ids, T)]
    for (a, b), Z, I in zip(graph["edges"], graph["Z"], info):
        lines.append(" ".join([tag[1], str(int(ids[a])), str(int(ids[b]))]
                              + [repr(float(v)) for v in pose(Z) + list(I[iu])]))
    Path(path).write_text("\n".join(lines) + "\n")
