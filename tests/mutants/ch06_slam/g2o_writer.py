"""Chapter 6 mutants, 6.27 `write_g2o`: writers with one slip each (see the package docstring).

A standalone writer (numpy and scipy's Rotation, like a learner's), not the grader's reader nor GTSAM's writer;
each mutant switches on exactly one mistake.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

MUTANTS: list[tuple] = []


def _write_with(path, graph, *, triangle="upper", permute=True, wxyz=False, degrees=False, inverse=False,
                fmt="{!r}", ids_as_rows=False):
    T, edges, Z, info = (np.asarray(graph[k]) for k in ("T", "edges", "Z", "info"))
    ids = np.arange(len(T)) if ids_as_rows else np.asarray(graph["ids"])
    d = T.shape[-1] - 1
    if inverse:
        Z = np.linalg.inv(Z)

    def pose(P):
        if d == 2:
            theta = np.arctan2(P[1, 0], P[0, 0])
            return [P[0, 2], P[1, 2], np.degrees(theta) if degrees else theta]
        q = Rotation.from_matrix(P[:3, :3]).as_quat()
        return list(P[:3, 3]) + list(q[[3, 0, 1, 2]] if wxyz else q)

    if d == 3 and permute:
        o = [3, 4, 5, 0, 1, 2]
        info = info[:, o][:, :, o]
    k = info.shape[-1]
    pick = {"upper": np.triu_indices(k), "lower": np.tril_indices(k)}.get(triangle)

    def numbers(values):
        return [fmt.format(float(v)) for v in values]

    tag = ("VERTEX_SE2", "EDGE_SE2") if d == 2 else ("VERTEX_SE3:QUAT", "EDGE_SE3:QUAT")
    lines = [" ".join([tag[0], str(int(i))] + numbers(pose(P))) for i, P in zip(ids, T)]
    for (a, b), Zab, I in zip(edges, Z, info):
        upper = I.ravel() if triangle == "full" else I[pick]
        lines.append(" ".join([tag[1], str(int(ids[a])), str(int(ids[b]))] + numbers(pose(Zab) + list(upper))))
    Path(path).write_text("\n".join(lines) + "\n")


def write_lower_triangle(path, graph):
    _write_with(path, graph, triangle="lower")


def write_full_matrix(path, graph):
    _write_with(path, graph, triangle="full")


def write_info_not_permuted(path, graph):
    _write_with(path, graph, permute=False)


def write_quaternion_wxyz(path, graph):
    _write_with(path, graph, wxyz=True)


def write_theta_degrees(path, graph):
    _write_with(path, graph, degrees=True)


def write_inverse_measurement(path, graph):
    _write_with(path, graph, inverse=True)


def write_three_decimals(path, graph):
    _write_with(path, graph, fmt="{:.3f}")


def write_row_numbers_as_ids(path, graph):
    _write_with(path, graph, ids_as_rows=True)


def write_nothing(path, graph):
    """Builds the text and returns it instead of writing the file."""
    return "\n".join(f"VERTEX_SE2 {int(i)} 0 0 0" for i in graph["ids"])


MUTANTS += [
    ("6.27", "information lower triangle row by row", write_lower_triangle, "upper triangle row by row"),
    ("6.27", "full information matrix written", write_full_matrix, "full information matrix"),
    ("6.27", "SE(3) information left rotation first", write_info_not_permuted, "permute rows and columns back"),
    ("6.27", "quaternion written w x y z", write_quaternion_wxyz, "w first"),
    ("6.27", "SE(2) theta in degrees", write_theta_degrees, "degrees"),
    ("6.27", "inverse measurement written", write_inverse_measurement, "inverted"),
    ("6.27", "three decimals (%.3f)", write_three_decimals, "lost digits"),
    ("6.27", "row numbers written as ids", write_row_numbers_as_ids, "row numbers"),
    ("6.27", "text returned, no file written", write_nothing, "no file at the path"),
]
