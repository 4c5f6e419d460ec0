"""Chapter 4, section 4.15 — rotation averaging (chordal L2).

Oracle: the chordal L2 linear system with the gauge R_0 = I, each block projected onto SO(3); judged after
the best global rotation.
"""
from __future__ import annotations

import numpy as np

from graders.kit import scene
from graders.core.compare import rotation_angle_deg
from graders.core.engine import as_rotation, Case, Exercise, Hint, OutputError, register
from graders.kit.geometry import project_to_so3


def gt_rotation_averaging(R_rel: dict, n: int) -> np.ndarray:
    """Chordal L2: R_j - R_ij R_i = 0 for every edge as a linear system in the 9n entries (rows of the
    stacked [R_0; ...] solved column-wise as 3 vectors), R_0 = I fixes the gauge, then each block is
    projected onto SO(3)."""
    m = 3 * n
    rows = []
    for (i, j), Rij in R_rel.items():       # (E_j - R_ij E_i) Y = 0, Y = [R_0; ...; R_{n-1}]: (3n, 3)
        row = np.zeros((3, m))
        row[:, 3 * j:3 * j + 3] = np.eye(3)
        row[:, 3 * i:3 * i + 3] -= np.asarray(Rij, float)
        rows.append(row)
    A = np.concatenate(rows)                # (3E, 3n): acts on each column of the stacked rotations
    fix = np.zeros((3, m))
    fix[:, :3] = np.eye(3)
    A = np.r_[A, 10.0 * fix]
    B = np.r_[np.zeros((A.shape[0] - 3, 3)), 10.0 * np.eye(3)]
    Xs = np.linalg.solve(A.T @ A, A.T @ B)      # normal equations (3n x 3n, well conditioned by the gauge rows):
    return np.stack([project_to_so3(Xs[3 * i:3 * i + 3]) for i in range(n)])   # lstsq's SVD is ~100x slower


def align_rotations(Rs: np.ndarray, Rs_true: np.ndarray) -> np.ndarray:
    """Errors (°) per camera after the best global rotation G (R_i G ≈ R_i^true)."""
    G = project_to_so3(sum(a.T @ b for a, b in zip(Rs, Rs_true)))
    return np.array([rotation_angle_deg(a @ G, b) for a, b in zip(Rs, Rs_true)])


def rotation_graph(rng: np.random.Generator, n: int, extra: float = 0.3, noise_deg: float = 0.0, outliers: int = 0):
    """n random world-to-camera rotations; edges: a spanning chain plus a fraction of the other pairs;
    R_ij = R_j R_iᵀ perturbed by a random rotation of noise_deg (Gaussian angle)."""
    Rs = np.stack([scene.random_rotation(rng) for _ in range(n)])
    edges = [(i, i + 1) for i in range(n - 1)]
    edges += [(i, j) for i in range(n) for j in range(i + 2, n) if rng.random() < extra]
    R_rel = {}
    for i, j in edges:
        noise = scene.rotation_about(rng.normal(size=3), np.radians(noise_deg) * abs(rng.normal())) \
            if noise_deg else np.eye(3)
        R_rel[(i, j)] = noise @ Rs[j] @ Rs[i].T
    return Rs, R_rel


def _convert_rotations(out, case):
    n = case.args[1]
    try:
        Rs = np.asarray(out, float)
    except Exception:
        raise OutputError(f"expected an ({n}, 3, 3) array of rotations") from None
    if Rs.shape != (n, 3, 3):
        raise OutputError(f"expected shape ({n}, 3, 3), got {Rs.shape}")
    for i, R in enumerate(Rs):
        as_rotation(R, f"R[{i}]")
    return Rs


def cases_rotation_averaging(rng: np.random.Generator) -> list[Case]:
    out = []
    Rs, R_rel = rotation_graph(rng, 12, 0.3)
    # exact relative rotations: every camera within 1e-4° after the global gauge rotation (the angle
    # comes from arccos((tr − 1) / 2), which cannot resolve less than ~1e-6°).
    out.append(Case("12 cameras, exact relative rotations", (R_rel, 12), Rs,
                    lambda o, e: float(align_rotations(o, e).max()), 1e-4, "° (max, after gauge)",
                    convert=_convert_rotations, key="exact", tags=("exact",)))
    for name, n, extra, noise in [("30 cameras, 40 % of pairs, 2° noise", 30, 0.4, 2.0),
                                  ("a long loop of 40 cameras (chain + 5 % of pairs), 1° noise", 40, 0.05, 1.0)]:
        Rs, R_rel = rotation_graph(rng, n, extra, noise)
        ref = float(np.mean(align_rotations(gt_rotation_averaging(R_rel, n), Rs)))
        # Mean error after the gauge vs the truth: 1.3 x the grader's chordal L2 + 0.05°. Chaining
        # relative rotations along a spanning tree (ignoring the loops) accumulates noise: 2-6x worse.
        out.append(Case(f"{name} (chordal L2: {ref:.2f}°)", (R_rel, n), Rs,
                        lambda o, e: float(np.mean(align_rotations(o, e))), 1.3 * ref + 0.05, "° (mean, after gauge)",
                        convert=_convert_rotations, key=f"noisy-{n}", tags=("noise",)))
    return out


def _spanning_tree(c):
    R_rel, n = c.args
    Rs = [None] * n
    Rs[0] = np.eye(3)
    for k in range(1, n):
        Rs[k] = R_rel[(k - 1, k)] @ Rs[k - 1]
    return np.stack(Rs)


ROTAVG_HINTS = [
    Hint("you chained the relative rotations along a tree: the other edges (the loops) are ignored and the noise "
         "adds up. Solve all the constraints R_j = R_ij R_i at once (least squares), then project onto SO(3).",
         lambda c, out: 30 > float(np.mean(align_rotations(out, c.expected))) >=
         0.9 * float(np.mean(align_rotations(_spanning_tree(c), c.expected))) and "noise" in c.tags),
    Hint("wrong even with exact relative rotations: check the convention R_ij = R_j R_iᵀ (so R_j = R_ij R_i; "
         "R_i R_jᵀ is the inverse).", lambda c, out: "exact" in c.tags and c.metric(out, c.expected) > 1.0),
]


register(
    Exercise(id="4.15", title="Rotation averaging (chordal L2)", name="rotation_averaging", kind="code", points=3,
             cases=cases_rotation_averaging, hints=ROTAVG_HINTS, fallback=gt_rotation_averaging,
             arg_names=("R_rel", "n")),
)
