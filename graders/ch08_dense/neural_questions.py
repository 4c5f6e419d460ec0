"""Chapter 8's neural CONCEPT (8.4-8.7) and DESIGN (8.22-8.23) questions; every answer computed here.

Sources: Mildenhall et al., "NeRF", ECCV 2020 (eq. 3 quadrature, eq. 4 positional encoding with L = 10 for
positions and L = 4 for directions — 60 and 24 values, the released code also appends the input, 63 and 27;
N_c = 64 coarse and N_f = 128 fine samples, the fine network evaluated at all 64 + 128; the 8 × 256 MLP with
a skip at the 5th layer); Kerbl et al., "3D Gaussian Splatting", SIGGRAPH 2023 (μ, q, s, opacity and
degree-3 SH: 16 coefficients per colour channel; Σ = R S Sᵀ Rᵀ; EWA Σ' = J W Σ Wᵀ Jᵀ; 16 × 16 tiles, one
radix sort; stop at T < 1e-4; clone / split by the view-space gradient > 0.0002, split scale / 1.6, prune
o < 0.005, opacity reset every 3000 iterations); the reference rasteriser's 0.3 px² dilation.
"""
from __future__ import annotations

import numpy as np

from graders.core.compare import relative
from graders.core.engine import choice_question, numeric_question, register, value_hint

# ----------------------------------------------------------------- 8.4 NeRF quadrature
SIGMAS, DELTA = np.array([0.0, 1.0, 4.0, 2.0]), 0.5       # four samples 0.5 m apart, σ in 1/m


def quadrature(sigma=SIGMAS, delta=DELTA, inclusive=False, linear=False) -> np.ndarray:
    """(w_0, w_1, w_2, w_3, opacity) of eq. 3 (inclusive / linear: the two classic slips)."""
    a = np.minimum(sigma * delta, 1) if linear else 1 - np.exp(-sigma * delta)
    T = np.cumprod(1 - a) if inclusive else np.cumprod(np.r_[1.0, 1 - a[:-1]])
    w = T * a
    return np.r_[w, w.sum()]


QUAD = quadrature()

# ----------------------------------------------------------------- 8.5 positional encoding, hierarchical sampling
L_POS, N_C, N_F = 10, 64, 128
BINS, W_COARSE, U = np.array([2.0, 3, 4, 5, 6]), np.array([0.1, 0.6, 0.2, 0.1]), 0.5


def encoding_numbers() -> np.ndarray:
    """(length of γ(x) for x ∈ R³ with L = 10 as in eq. 4, the fine sample at quantile 0.5 of the coarse
    weights, MLP evaluations per ray)."""
    cdf = np.r_[0, np.cumsum(W_COARSE) / W_COARSE.sum()]
    return np.array([3 * 2 * L_POS, np.interp(U, cdf, BINS), N_C + (N_C + N_F)])


ENC = encoding_numbers()

# ----------------------------------------------------------------- 8.6 3DGS parameters and memory
SH_DEGREE, N_SCENE = 3, 1_000_000


def gaussian_numbers(degree=SH_DEGREE, N=N_SCENE) -> np.ndarray:
    """(floats per Gaussian, bytes in float32, MB for N Gaussians)."""
    floats = 3 + 4 + 3 + 1 + 3 * (degree + 1) ** 2          # μ, q, s, opacity, SH per channel
    return np.array([floats, 4 * floats, 4 * floats * N / 1e6])


GAUSS = gaussian_numbers()

# ----------------------------------------------------------------- 8.7 the rasteriser and density control
RASTER_SCENARIOS = [
    ("a Gaussian 0.4 px wide in an under-reconstructed region has a large view-space position gradient", "clone"),
    ("a Gaussian 30 px wide over fine texture has a large view-space position gradient", "split"),
    ("a Gaussian's opacity has fallen to 0.003", "prune"),
    ("semi-transparent blobs float in front of the cameras and keep their opacity because each explains one view; "
     "iteration 3000 is reached", "reset"),
    ("a distant Gaussian projects to 0.2 px and would flicker between pixels as the camera moves", "dilate"),
    ("a pixel's transmittance has just fallen below 1e-4 halfway down its tile's list", "stop"),
]
RASTER_OPTIONS = ["clone", "split", "prune", "reset", "dilate", "stop"]

# ----------------------------------------------------------------- 8.22 memory at N Gaussians
N_BIG = 3_200_000


def memory_numbers(N=N_BIG) -> np.ndarray:
    """(MB at degree-3 SH, MB at degree 0, MB while training with Adam: params + grads + 2 moments)."""
    g3, g0 = gaussian_numbers(3, N)[2], gaussian_numbers(0, N)[2]
    return np.array([g3, g0, 4 * g3])


MEM = memory_numbers()

# ----------------------------------------------------------------- 8.23 NeRF FLOPs per frame
H_IMG = W_IMG = 800
TFLOPS = 10.0                                               # sustained FP32 throughput of a desktop GPU


def mlp_macs() -> int:
    """NeRF's MLP: 63 → 256, 3 × 256², (256 + 63) → 256 skip, 3 × 256², σ head, 256 feature, (256 + 27) → 128 → 3."""
    layers = [(63, 256)] + [(256, 256)] * 4 + [(256 + 63, 256)] + [(256, 256)] * 2 + [(256, 1), (256, 256),
                                                                                      (256 + 27, 128), (128, 3)]
    return sum(a * b for a, b in layers)


def flops_numbers() -> np.ndarray:
    """(rays per frame, MLP evaluations per frame, TFLOP per frame (2 FLOP per MAC), seconds at 10 TFLOP/s)."""
    rays = H_IMG * W_IMG
    evals = rays * (N_C + N_C + N_F)
    tflop = 2 * mlp_macs() * evals / 1e12
    return np.array([rays, evals, tflop, tflop / TFLOPS])


FLOPS = flops_numbers()

register(
    numeric_question(
        "8.4", "NeRF's quadrature on one ray", "quadrature_weights", "concept", QUAD, 1e-3, "rel.", (5,), relative,
        "α_i = 1 − exp(−σ_i δ_i) = (0, 0.393, 0.865, 0.632); T_i = Π_{j<i}(1 − α_j) = (1, 1, 0.607, 0.082); "
        f"w = T α = ({', '.join(f'{x:.3f}' for x in QUAD[:4])}), opacity Σw = 1 − T_far = {QUAD[4]:.3f} ≤ 1: the rest "
        "of the light comes from the background. The weights are a distribution of where the ray stops; its mean "
        "is the depth map. Misconception: a NeRF does not 'understand geometry' — σ is whatever density makes the "
        "training views' colours come out; with few views, shiny or textureless surfaces, it puts density in the "
        "wrong place (floaters, fog, a reflection painted as a hole) and the depth map shows it.",
        hints=[value_hint(quadrature(inclusive=True), "T_i is the product over j < i: sample i's own α is not in "
                                                      "its transmittance (T_0 = 1)."),
               value_hint(quadrature(linear=True), "α = 1 − exp(−σδ), not σδ (which exceeds 1 for σδ > 1).")]),
    numeric_question(
        "8.5", "Positional encoding and hierarchical sampling", "encoding_numbers", "concept", ENC, 1e-3, "rel.", (3,),
        relative,
        "γ(p) = (sin 2⁰πp, cos 2⁰πp, …, sin 2^{L−1}πp, cos 2^{L−1}πp) per coordinate: 2L = 20 values each, "
        f"{ENC[0]:.0f} for a 3D point (the released code also appends p: 63). Why: an MLP on raw (x, y, z) is "
        "biased towards low frequencies (spectral bias) and renders blur; the sinusoids up to 2⁹π let it fit "
        "detail of ~1/1000 of the scene. Inverse CDF: CDF = (0, 0.1, 0.7, 0.9, 1); u = 0.5 falls in [3, 4): "
        f"t = 3 + (0.5 − 0.1)/0.6 = {ENC[1]:.3f}. The coarse network runs at N_c = 64 samples, the fine one at "
        f"all 64 + 128: {ENC[2]:.0f} evaluations per ray.",
        hints=[value_hint([3 * 2 * L_POS + 3, ENC[1], ENC[2]], "(a) eq. 4's γ has 2L values per coordinate: 60 "
                                                                "(63 is the code's, which appends p itself)."),
               value_hint([ENC[0], ENC[1], N_C + N_F], "(c) the fine network evaluates the 128 new samples AND the "
                                                       "64 coarse ones (sorted together): 64 + 192.")]),
    numeric_question(
        "8.6", "3DGS parameters and memory", "gaussian_numbers", "concept", GAUSS, 1e-3, "rel.", (3,), relative,
        "Per Gaussian: μ (3), quaternion q (4), scale s (3), opacity (1), and view-dependent colour as spherical "
        "harmonics up to degree 3: (3 + 1)² = 16 coefficients per channel, 48 floats — "
        f"{GAUSS[0]:.0f} floats, {GAUSS[1]:.0f} B in float32 (the .ply files also store 3 unused normals: 248 B), "
        f"{GAUSS[2]:.0f} MB for 1 M Gaussians; real scenes hold 1-6 M. SH is 81 % of it, the first target of "
        "compression. Misconception: '3DGS is always better than NeRF' — it renders 100+ FPS and trains in "
        "minutes, but needs an SfM initialisation, is 10-100× larger than a NeRF, and shows floaters and "
        "needle-like Gaussians in sparse-view or unbounded scenes where NeRF variants degrade more gracefully.",
        hints=[value_hint(gaussian_numbers() - np.array([32, 128, 128]),
                          "degree-3 SH has (3 + 1)² = 16 coefficients per colour channel, 48 floats, not 16.")]),
    choice_question(
        "8.7", "The 3DGS rasteriser and its density control", "raster_decisions", "concept",
        [s[1] for s in RASTER_SCENARIOS], RASTER_OPTIONS,
        "Σ = R S Sᵀ Rᵀ stays a valid covariance whatever the optimiser does to q and s. EWA: Σ' = J W Σ Wᵀ Jᵀ "
        "(the perspective map linearised at the mean), plus 0.3 px² on the diagonal so sub-pixel Gaussians cover a "
        "pixel and do not alias. The image is cut into 16 × 16 tiles; each Gaussian is duplicated into every tile "
        "its 3σ radius touches; one radix sort on (tile, depth) keys orders every tile; pixels composite front to "
        "back and stop when T < 1e-4. Density control (every 100 iterations up to 15 k): large view-space gradient "
        "(> 0.0002) and small → clone; large → split into two, scales / 1.6; opacity < 0.005 → prune; every 3000 "
        "iterations the opacities are reset to ≤ 0.01 so that floaters the views do not need fade and get pruned.",
        hints={0: "(a) small and under-reconstructed: clone it (a copy moves along the gradient).",
               1: "(b) one large Gaussian over detail: split it into two 1.6× smaller ones.",
               3: "(d) floaters keep their opacity: the periodic opacity reset makes every Gaussian earn it back."}),
    numeric_question(
        "8.22", "Memory of a 3DGS scene", "memory_numbers", "design", MEM, 1e-3, "rel.", (3,), relative,
        f"3.2 M × 236 B = {MEM[0]:.0f} MB with degree-3 SH; degree 0 keeps 3 colour floats (14 floats, 56 B): "
        f"{MEM[1]:.0f} MB — view-dependent colour is most of the memory. Training keeps parameters, gradients and "
        f"Adam's two moments: 4 × = {MEM[2]:.0f} MB, plus the per-tile lists and the images (so 24 GB GPUs).",
        hints=[value_hint(MEM * np.array([1, 1, 0.75]), "(c) Adam keeps two moments per parameter besides the "
                                                        "parameter and its gradient: 4 copies, not 3.")]),
    numeric_question(
        "8.23", "NeRF FLOPs per frame", "flops_numbers", "design", FLOPS, 0.02, "rel.", (4,), relative,
        f"800 × 800 = {FLOPS[0]:.0f} rays; 64 coarse + (64 + 128) fine = 256 MLP evaluations per ray: "
        f"{FLOPS[1]:.3g} per frame; the MLP has {mlp_macs()} multiply-adds ({2 * mlp_macs() / 1e6:.2f} MFLOP) per "
        f"evaluation: {FLOPS[2]:.0f} TFLOP per frame, {FLOPS[3]:.0f} s at 10 TFLOP/s — why NeRF renders in "
        "seconds and why its successors replace most of the MLP by grids (Instant-NGP) or by rasterised Gaussians.",
        hints=[value_hint(FLOPS * np.array([1, (N_C + N_F) / 256, (N_C + N_F) / 256, (N_C + N_F) / 256]),
                          "(b) the fine network also re-evaluates the 64 coarse samples: 256 evaluations per ray."),
               value_hint(FLOPS * np.array([1, 1, 0.5, 0.5]), "(c) one multiply-add is 2 FLOP.")]),
)
