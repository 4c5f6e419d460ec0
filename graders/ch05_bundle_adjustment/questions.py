"""Chapter 5's CONCEPT (5.1-5.4) and DESIGN (5.19-5.22) questions; each answer computed here, never pasted."""
from __future__ import annotations

import numpy as np

from graders.core.compare import max_abs, relative
from graders.core.engine import Hint, numeric_question, register, value_hint


def _lm_answer():
    JtJ, g, lam = np.array([[4.0, 0.0], [0.0, 1.0]]), np.array([2.0, -1.0]), 1.0
    dx = np.linalg.solve(JtJ + lam * np.eye(2), -g)
    predicted = 0.5 * dx @ (lam * dx - g)
    rho = 0.6 / predicted
    return np.r_[dx, rho, lam * max(1 / 3, 1 - (2 * rho - 1) ** 3)]


LM_ANSWER = _lm_answer()


register(
    # 0.002 percentage points: the answer 99.9706 % rounded to 3 decimals passes; the share of
    # nonzeros (0.03 %) or 12 nonzeros per row (99.9608 %) do not.
    numeric_question(
        id="5.1",
        title="How sparse is the BA Jacobian?",
        name="jacobian_zero_pct",
        kind="concept",
        expected=100 * (1 - 9 / 30_600),
        tol=0.002,
        unit="%",
        shape=(),
        metric=max_abs,
        explanation="J has 2M rows and 100·6 + 10,000·3 = 30,600 columns; each row touches one camera (6) and one point (3): "
            "9 nonzeros. Zeros: 1 − 9/30,600 = 99.9706 % — 18 M nonzeros out of 61.2 billion entries.",
        hints=[value_hint(100 * 9 / 30_600, "that is the share of nonzeros; the question asks for zeros."),
             value_hint(100 * (1 - 12 / 30_600), "a row has 6 + 3 = 9 nonzeros in this question (poses only).")],
    ),
    # 0.02 relative: the answers rounded to 2-3 significant figures (7.5 GB, 2.9 MB) pass; GiB/MiB
    # instead of GB/MB (7 % and 5 % off) and counting entries instead of bytes (8x) do not.
    numeric_question(
        id="5.2",
        title="Full Hessian vs reduced camera system",
        name="hessian_memory",
        kind="concept",
        expected=[30_600**2 * 8 / 1e9, 600**2 * 8 / 1e6],
        tol=0.02,
        unit="rel.",
        shape=(2,),
        metric=relative,
        explanation="Full: 30,600² entries × 8 B = 7.49 GB. Reduced: 600² × 8 B = 2.88 MB. The Schur complement shrinks the "
            "system by (30,600/600)² = 2,601×, and V⁻¹ costs only 10,000 independent 3×3 inverses.",
        hints=[value_hint([30_600**2 / 1e9, 600**2 / 1e6], "that counts entries; each float64 takes 8 bytes."),
             value_hint([30_600**2 * 8 / 2**30, 600**2 * 8 / 2**20], "GiB and MiB: use 1 GB = 1e9 B and 1 MB = 1e6 B.")],
    ),
    # 2e-3 absolute on each of (dx1, dx2, rho, lambda): the values rounded to 3 decimals (-0.4, 0.5,
    # 0.702, 0.934) pass; 1/rho, the /10 rule (0.1) or a sign slip are off by > 0.05.
    numeric_question(
        id="5.3",
        title="One Levenberg-Marquardt step by hand",
        name="lm_step",
        kind="concept",
        expected=LM_ANSWER,
        tol=2e-3,
        unit="",
        shape=(4,),
        metric=max_abs,
        explanation="Δ = −(JᵀJ + λI)⁻¹ g = −(2/5, −1/2) = (−0.4, 0.5). Predicted decrease ½Δᵀ(λΔ − g) = ½(0.96 + 0.75) = 0.855, so "
            "ρ = 0.6 / 0.855 = 0.702 > 0: accept, and λ ← λ·max(1/3, 1 − (2ρ − 1)³) = 0.934 (Nielsen: a good but not "
            "perfect model lowers λ only a little; a fixed ÷10 rule would drop it to 0.1, far more aggressively).",
        hints=[Hint("the step must go downhill: Δ = −(JᵀJ + λI)⁻¹ g.", lambda c, out: out[0] > 0 and out[1] < 0),
             Hint("ρ is actual over predicted decrease (0.6 / 0.855), not the inverse.",
                  lambda c, out: abs(out[2] - 1 / LM_ANSWER[2]) < 2e-3),
             Hint("that is the ÷10 / ×10 rule; this question uses Nielsen's update λ·max(1/3, 1 − (2ρ − 1)³).",
                  lambda c, out: abs(out[3] - 0.1) < 2e-3 or abs(out[3] - 10) < 2e-3),
             Hint("the damping goes down after an accepted step with ρ > 0 (the model was trustworthy).",
                  lambda c, out: out[3] > 1.0)],
    ),
    # 1e-9: integer counts.
    numeric_question(
        id="5.4",
        title="Gauge freedom",
        name="gauge_dof",
        kind="concept",
        expected=[7, 6, 0],
        tol=1e-9,
        unit="",
        shape=(3,),
        metric=max_abs,
        explanation="Reprojection errors do not change under a similarity of the whole scene: 3 rotation + 3 translation + "
            "1 scale = 7 DOF (monocular). A stereo rig with a known baseline fixes the scale: 6. Absolute positions of "
            "the cameras (GPS-tagged, as a prior) fix all 7: 0. Without fixing them JᵀJ has a 7-dimensional null space.",
        hints=[Hint("monocular BA has 7: rotation, translation *and* scale are unobservable from images alone.",
                  lambda c, out: out[0] == 6),
             Hint("a known baseline fixes the scale: only the rigid motion (6) remains.", lambda c, out: out[1] == 7)],
    ),
    # 0.02 relative: 288 MB rounded to 2 significant figures (290) passes; MiB (275, 4.6 % off) and
    # 9 parameters per camera (648 MB) do not.
    numeric_question(
        id="5.19",
        title="The reduced camera system at 1,000 cameras",
        name="schur_memory_mb",
        kind="design",
        expected=6000**2 * 8 / 1e6,
        tol=0.02,
        unit="rel.",
        shape=(),
        metric=relative,
        explanation="1,000 cameras × 6 = 6,000 unknowns; 6,000² × 8 B = 288 MB: a dense Cholesky is still fine (a few seconds). "
            "The unreduced system would have ~3 M unknowns: 72 TB dense.",
        hints=[value_hint(6000**2 * 8 / 2**20, "MiB: use 1 MB = 1e6 bytes."),
             value_hint(9000**2 * 8 / 1e6, "the question counts 6 pose parameters per camera (intrinsics fixed).")],
    ),
    # 1e-9: choice indices.
    numeric_question(
        id="5.20",
        title="Choose the linear solver",
        name="solver_choice",
        kind="design",
        expected=[0, 1, 2],
        tol=1e-9,
        unit="",
        shape=(3,),
        metric=max_abs,
        explanation="(a) 20 keyframes: S is 120×120 (115 kB) — dense Schur, done in microseconds. (b) 600 images: S is "
            "3,600² (104 MB dense) but each camera shares points with only a few dozen others, so S is sparse: sparse "
            "Schur (sparse Cholesky). (c) 20,000 cameras: 120,000² × 8 B = 115 GB dense, and the fill-in of a sparse "
            "factorisation explodes too: iterative Schur (PCG on S, never factorised). Ceres/COLMAP switch at about "
            "50 and 1,000 images.",
        hints=[Hint("(c): a 120,000-unknown reduced system is 115 GB dense; only an iterative solver avoids "
                  "factorising it.", lambda c, out: out[2] != 2)],
    ),
    # 0.02 relative: 0.0288 MB and 7,200 MB rounded to 2 significant figures pass; bytes instead of MB
    # (1e6x) and MiB (4.6 % off) do not.
    numeric_question(
        id="5.21",
        title="Local vs global BA in SLAM",
        name="local_global_mb",
        kind="design",
        expected=[60**2 * 8 / 1e6, 30_000**2 * 8 / 1e6],
        tol=0.02,
        unit="rel.",
        shape=(2,),
        metric=relative,
        explanation="Local BA: 10 keyframes × 6 = 60 unknowns, 60² × 8 B = 28.8 kB — solvable every keyframe in milliseconds. "
            "Global BA: 30,000² × 8 B = 7.2 GB dense — seconds to minutes, so it runs only after a loop closure, in a "
            "background thread, while tracking continues on the local map.",
        hints=[Hint("bytes: the answer is in MB (1e6 bytes).", lambda c, out: out[1] > 1e8)],
    ),
    # 0.5 ms: 38 ms to the nearest ms passes; 50 ms (all 20 ms slowed down) and 30 ms (the unchanged
    # 8 ms left out) do not.
    numeric_question(
        id="5.22",
        title="Autodiff at 30 Hz",
        name="autodiff_ms",
        kind="design",
        expected=0.4 * 20 + 0.6 * 20 * 2.5,
        tol=0.5,
        unit="ms",
        shape=(),
        metric=max_abs,
        explanation="Only the Jacobian evaluation slows down: 8 ms (linear algebra and the rest) + 12 ms × 2.5 = 38 ms > 33 ms: "
            "autodiff breaks the 30 Hz budget that analytic Jacobians meet — why ORB-SLAM3 derives them by hand.",
        hints=[value_hint(20 * 2.5, "only the Jacobian part (60 %) gets 2.5× slower; the linear solve does not."),
             value_hint(20 * 0.6 * 2.5, "add the 40 % that does not change (8 ms).")],
    ),
)

