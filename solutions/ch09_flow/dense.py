"""Exercises 9.12-9.13: Horn-Schunck, and a coarse-to-fine robust variational flow (Horn-Schunck's
smoothness with LK's window in the data term, Charbonnier weights, warping and median filtering), fused with
the dominant motion. Every pixel is solved at once: whole-image arrays, no loop over pixels.

Images (H, W) float grey levels; flow (H, W, 2) = (u, v) px.
"""
from __future__ import annotations

import numpy as np
from numpy.lib.stride_tricks import sliding_window_view
from scipy.ndimage import correlate, gaussian_filter, maximum_filter1d

from .tools import bilinear

# Horn and Schunck's weighted neighbour average (1981, eq. 9): 1/6 for the 4 neighbours, 1/12 diagonals.
HS_AVERAGE = np.array([[1 / 12, 1 / 6, 1 / 12], [1 / 6, 0.0, 1 / 6], [1 / 12, 1 / 6, 1 / 12]])


def horn_schunck(I1: np.ndarray, I2: np.ndarray, alpha: float = 10.0, iters: int = 100) -> np.ndarray:
    """Exercise 9.12: Horn-Schunck flow after `iters` Jacobi sweeps from zero. -> (H, W, 2).

    I_x, I_y: np.gradient of I1 (central differences, one-sided at the border); I_t = I2 − I1. Each sweep
    ū, v̄ = HS_AVERAGE ⊛ (u, v) (borders replicated), then
        u = ū − I_x (I_x ū + I_y v̄ + I_t) / (α² + I_x² + I_y²),   v likewise with I_y:
    the minimiser of Σ (I_x u + I_y v + I_t)² + α² |∇u|² + α² |∇v|² with the Laplacian written as ū − u."""
    I1, I2 = np.asarray(I1, float), np.asarray(I2, float)
    Iy, Ix = np.gradient(I1)
    It = I2 - I1
    den = alpha ** 2 + Ix ** 2 + Iy ** 2
    u, v = np.zeros_like(I1), np.zeros_like(I1)
    for _ in range(iters):
        ub, vb = correlate(u, HS_AVERAGE, mode="nearest"), correlate(v, HS_AVERAGE, mode="nearest")
        r = (Ix * ub + Iy * vb + It) / den
        u, v = ub - Ix * r, vb - Iy * r
    return np.stack([u, v], -1)


def _merge_exchange(n: int) -> list[tuple[int, int]]:
    """Batcher's odd-even merge sort as a list of compare-exchanges (i, j), i < j: after each, position i holds
    the smaller value and j the larger; after all of them, any n values are sorted (Knuth, TAOCP vol. 3,
    5.2.2, Algorithm M: 138 compare-exchanges for n = 25). The same steps for every input: a sorting network."""
    t = max(1, (n - 1).bit_length())
    pairs, p = [], 1 << (t - 1)
    while p > 0:
        q, r, d = 1 << (t - 1), 0, p
        while True:
            pairs += [(i, i + d) for i in range(n - d) if i & p == r]
            if q == p:
                break
            d, q, r = q - p, q // 2, p
        p //= 2
    return pairs


def _median_network(n: int) -> list[tuple[int, int]]:
    """The compare-exchanges of `_merge_exchange(n)` that can change what ends up in the middle position n // 2
    (walking back from the end: a step matters if it writes a position that a later kept step reads):
    113 of 138 for n = 25."""
    needed, kept = {n // 2}, []
    for i, j in reversed(_merge_exchange(n)):
        if i in needed or j in needed:
            kept.append((i, j))
            needed |= {i, j}
    return kept[::-1]


MEDIAN25 = _median_network(25)


def median5(a: np.ndarray, where: np.ndarray | None = None) -> np.ndarray:
    """5 x 5 median filter over the last two axes, borders replicated (scipy.ndimage.median_filter(a, 5,
    mode="nearest") on each (H, W) image of a (..., H, W) array), in float32 (a median only selects: the float64
    result rounded to 7 digits, 1e-5 px on an 80 px flow).

    A sorting network (MEDIAN25) run on whole images at once: 25 arrays, one per window offset, hold each
    pixel's 25 neighbours at the same index; a compare-exchange is np.minimum and np.maximum of two of them;
    after the network the middle array holds every pixel's median. 113 whole-array min / max pairs, ~3x faster
    than sorting each pixel's 25 values (np.partition, one call per pixel inside numpy), in bands of ~16,000
    values (rows x width x images) so the 25 arrays stay in the CPU's L2 cache.
    where: (H, W) bool, if given: the median only there (the 25 neighbours of those pixels only), `a` elsewhere."""
    a = np.asarray(a, np.float32)
    H, W = a.shape[-2:]
    P = np.pad(a, [(0, 0)] * (a.ndim - 2) + [(2, 2), (2, 2)], mode="edge")
    if where is None:
        out = np.empty_like(a)
        rows = max(1, 16384 // (a.size // H))
        for y in range(0, H, rows):
            h = min(rows, H - y)
            band = [P[..., y + dy:y + dy + h, dx:dx + W] for dy in range(5) for dx in range(5)]   # 25 shifted views
            out[..., y:y + h, :] = _median25(band)
        return out
    ys, xs = np.nonzero(where)                      # pixel (y, x)'s window starts at (y, x) in P
    P = P.reshape(P.shape[:-2] + (-1,))
    start = ys * (W + 4) + xs
    out = a.copy()
    n = max(1, 16384 // (a.size // (H * W)))
    for i in range(0, len(start), n):
        s = start[i:i + n]
        med = _median25([np.take(P, s + dy * (W + 4) + dx, axis=-1) for dy in range(5) for dx in range(5)])
        out[..., ys[i:i + n], xs[i:i + n]] = med
    return out


def _median25(v: list[np.ndarray]) -> np.ndarray:
    """The element-wise median of 25 equal-shaped arrays by the network MEDIAN25 (v is not modified)."""
    v = [x.copy() for x in v]
    low = np.empty_like(v[0])
    for i, j in MEDIAN25:                    # compare-exchange: v[i] <- min, v[j] <- max (no fresh arrays)
        np.minimum(v[i], v[j], out=low)
        np.maximum(v[i], v[j], out=v[j])
        v[i], low = low, v[i]
    return v[12]


def _median_flow(f: np.ndarray, where: np.ndarray | None = None) -> np.ndarray:
    """median5 of each flow component (H, W, 2) -> (H, W, 2) float32."""
    return np.stack(list(median5(np.moveaxis(f, -1, 0), where)), -1)


def _neighbour_sum(u: np.ndarray, wx: np.ndarray, wy: np.ndarray) -> np.ndarray:
    """Σ_n w_pn u_n over the 4 neighbours n of every pixel p; wx (H, W-1) weighs the link p -> p + x̂,
    wy (H-1, W) the link p -> p + ŷ (the same weight seen from both ends). Missing neighbours weigh 0."""
    out = np.zeros_like(u)
    out[:, :-1] += wx * u[:, 1:]
    out[:, 1:] += wx * u[:, :-1]
    out[:-1] += wy * u[1:]
    out[1:] += wy * u[:-1]
    return out


def _link_weights(I: np.ndarray, f: np.ndarray, tau: float, eps: float) -> tuple[np.ndarray, np.ndarray]:
    """Smoothness weight of each link between 4-neighbours: exp(−|ΔI| / τ) (motion edges are usually image
    edges: smooth less across them) times the Charbonnier weight ε / sqrt(|Δf|² + ε²) of the current flow's
    difference (the lagged IRLS weight of sqrt(|∇f|² + ε²), TV-like: a motion edge is not smoothed away)."""
    dI = lambda a, ax: np.diff(a, axis=ax)                                      # noqa: E731
    w = []
    for ax in (1, 0):
        df2 = dI(f[..., 0], ax) ** 2 + dI(f[..., 1], ax) ** 2
        w.append(np.exp(-np.abs(dI(I, ax)) / tau) * eps / np.sqrt(df2 + eps * eps))
    return w[0], w[1]


def _robust_warp_step(I1, I2, f, alpha, rho, eps, tau, sigma, sweeps, omega=1.0):
    """One warp of the robust variational flow at one level -> the new flow (H, W, 2), median-filtered.

    Warp I2 by f, linearise I2w(x + df) ≈ I2w + ∇I·df (∇I averaged over I1 and I2w), and minimise
        Σ_p ψ_p G_σ*(I_x du + I_y dv + I_t)²  +  α² Σ_links w_pn |(f + df)_p − (f + df)_n|²
    — the data term is Bruhn et al.'s combined local-global one (LK's window G_σ inside Horn-Schunck), ψ_p
    = 1 / sqrt(I_t² + ρ²) the Charbonnier weight of the warp residual (occluded pixels count less), w the
    link weights above. With J = G_σ*(ψ [I_x, I_y]ᵀ [I_x, I_y]) and j = G_σ*(ψ I_t [I_x, I_y]), setting the
    gradient to zero at pixel p gives, for the new flow w = f + df,
        (J + α² s_p I) w_p = α² Σ_n w_pn w_n + J f_p − j,   s_p = Σ_n w_pn,
    a 2 x 2 system per pixel, solved by its inverse (computed once per warp) for all pixels at once, in
    `sweeps` red-black SOR sweeps: the red half of a checkerboard from its black neighbours, then the black
    half from the new red ones (Gauss-Seidel, vectorised: 4-neighbours always differ in colour), each step
    over-relaxed by omega (1 < omega < 2; omega = 1 is Gauss-Seidel). 6 sweeps at omega 1.5 reach a lower
    EPE than the 20 Jacobi sweeps (the neighbours' w all from the previous sweep) it replaced, in ~2/3 of the
    time (FlyingChairs pairs, benchmarks/ch09_flow.py). Then Sun, Roth & Black's 5 x 5 median filter of the flow."""
    H, W = I1.shape
    xs, ys = np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32)[:, None]   # pixel coordinates
    I2w = bilinear(I2, xs + f[..., 0], ys + f[..., 1], np.float32)           # 9.9's backward warp
    (gy1, gx1), (gy2, gx2) = np.gradient(I1), np.gradient(I2w)
    Ix, Iy, It = 0.5 * (gx1 + gx2), 0.5 * (gy1 + gy2), I2w - I1
    psi = 1.0 / np.sqrt(It * It + rho * rho)
    psi /= psi.mean()                               # α keeps its meaning whatever the image's contrast
    S = lambda a: gaussian_filter(psi * a, sigma, mode="nearest")            # noqa: E731
    J11, J12, J22, j1, j2 = S(Ix * Ix), S(Ix * Iy), S(Iy * Iy), S(Ix * It), S(Iy * It)
    wx, wy = _link_weights(I1, f, tau, eps)
    wx, wy = alpha ** 2 * wx, alpha ** 2 * wy                                # α² w_pn, once
    a2s = _neighbour_sum(np.ones_like(I1), wx, wy)
    A11, A22 = J11 + a2s, J22 + a2s
    det = A11 * A22 - J12 * J12
    M11, M12, M22 = A22 / det, -J12 / det, A11 / det                        # each pixel's inverse, once
    b1 = J11 * f[..., 0] + J12 * f[..., 1] - j1
    b2 = J12 * f[..., 0] + J22 * f[..., 1] - j2
    u, v = f[..., 0].copy(), f[..., 1].copy()                               # updated in place below
    red = np.add.outer(np.arange(H), np.arange(W)) % 2 == 0                # a checkerboard
    halves = [np.where(m, np.float32(omega), np.float32(0)) for m in (red, ~red)]   # omega on one half, 0 on the other
    for _ in range(sweeps):
        for step in halves:        # red pixels' neighbours are all black: each half updates from the other's new w
            r1, r2 = b1 + _neighbour_sum(u, wx, wy), b2 + _neighbour_sum(v, wx, wy)
            un, vn = M11 * r1 + M12 * r2, M12 * r1 + M22 * r2                # the 2 x 2 solve, every pixel
            un -= u
            un *= step
            u += un                                 # u + omega (un - u) on this half (over-relaxed), u on the other
            vn -= v
            vn *= step
            v += vn
    return _median_flow(np.stack([u, v], -1))


def affine_motion(f: np.ndarray, step: int = 4, iters: int = 3) -> np.ndarray:
    """The dominant motion of a flow f (H, W, 2) as an affine field (H, W, 2) (a background that rotates or
    zooms is not a constant flow: 0.02 rad of rotation moves the corners of a 512 x 384 image by 6.4 px):
    least squares on every `step`-th pixel, refitted twice on the pixels within max(1 px, the median
    residual) of the fit (the moving objects drop out)."""
    H, W = f.shape[:2]
    x, y = np.arange(W, dtype=np.float32) / W, np.arange(H, dtype=np.float32) / H   # scaled for conditioning
    ys, xs = np.meshgrid(y[::step], x[::step], indexing="ij")
    A = np.stack([xs.ravel(), ys.ravel(), np.ones(xs.size)], 1).astype(float)   # rows (x / W, y / H, 1)
    b = f[::step, ::step].reshape(-1, 2).astype(float)
    keep = np.ones(len(A), bool)
    for _ in range(iters):
        P = np.linalg.lstsq(A[keep], b[keep], rcond=None)[0]                # (3, 2)
        r = np.linalg.norm(A @ P - b, axis=1)
        keep = r < max(1.0, float(np.median(r)))
    P = P.astype(np.float32)
    return x[None, :, None] * P[0] + y[:, None, None] * P[1] + P[2]         # (H, W, 2), by broadcasting


def _keep(I1, I2, f, T, k) -> np.ndarray:
    """Where f explains the images better than the candidate T: its local warp error |I2(x + f) − I1|,
    Gaussian-averaged over σ = 2, below k times T's. -> (H, W) bool."""
    H, W = I1.shape
    xs, ys = np.arange(W, dtype=np.float32), np.arange(H, dtype=np.float32)[:, None]
    I2 = np.asarray(I2, np.float32)                 # once (bilinear would convert it for each call)
    err = lambda g: gaussian_filter(np.abs(bilinear(I2, xs + g[..., 0], ys + g[..., 1], np.float32) - I1),  # noqa
                                    2.0)
    return err(f) < k * err(T)


def _fuse(I1, I2, f, T, k):
    """FusionFlow in its simplest form: per pixel, keep f where its local warp error is below k times the
    candidate T's (`_keep`), else take T."""
    return np.where(_keep(I1, I2, f, T, k)[..., None], f, T)


def _linear_weights(n: int, m: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Resampling n samples to m (pixel centres aligned, edges replicated): for each output sample, its two
    input neighbours i0, i0 + 1 (clipped) and the weight t of the second. -> (i0, i1, t), each (m,)."""
    x = np.clip((np.arange(m) + 0.5) * n / m - 0.5, 0, n - 1)
    i0 = np.minimum(x.astype(np.intp), n - 2) if n > 1 else np.zeros(m, np.intp)
    return i0, np.minimum(i0 + 1, n - 1), (x - i0).astype(np.float32)


def _resize_flow(f: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    """Bilinear upsampling of a flow to `shape`, its vectors scaled by the size ratio. Separable: linear
    interpolation along y (whole rows at once), then along x (whole columns), the same as 2-D bilinear."""
    H, W = shape
    h, w = f.shape[:2]
    f = np.asarray(f, np.float32) * np.float32([W / w, H / h])
    i0, i1, t = _linear_weights(h, H)
    f = f[i0] + t[:, None, None] * (f[i1] - f[i0])                           # (H, w, 2)
    j0, j1, t = _linear_weights(w, W)
    left = np.take(f, j0, axis=1)                   # np.take: columns gathered 2x faster than f[:, j0]
    return left + t[None, :, None] * (np.take(f, j1, axis=1) - left)         # (H, W, 2)


def gaussian_pyramids(I1, I2, min_size: int = 16) -> tuple[list, list]:
    """Both images blurred (σ = 1) and halved until the short side is ≤ 2 min_size, finest first (float32)."""
    P1, P2 = [gaussian_filter(np.float32(I1), 1.0)], [gaussian_filter(np.float32(I2), 1.0)]
    while min(P1[-1].shape) > 2 * min_size:
        P1.append(gaussian_filter(P1[-1], 1.0)[::2, ::2])
        P2.append(gaussian_filter(P2[-1], 1.0)[::2, ::2])
    return P1, P2


def dense_flow(I1: np.ndarray, I2: np.ndarray, alpha: float = 4.0, rho: float = 2.0, eps: float = 0.2,
               tau: float = 5.0, sigma: float = 0.7, warps: int = 3, sweeps: int = 6, omega: float = 1.5,
               min_size: int = 16, warps_half: int = 2) -> np.ndarray:
    """Exercise 9.13: coarse-to-fine robust variational flow, fused with the dominant motion. -> (H, W, 2).

    1. Gaussian pyramids (halving until the short side is ≤ 2 min_size). Coarse to fine, down to half
       resolution: upsample the flow ×2; fuse it with its own dominant affine motion (keep the flow where it
       explains the images at least as well: k = 1), which stops a fast object's motion dragged into the
       background at a coarse level from spreading further; then `warps` robust warp steps (warp, solve the
       linearised robust energy, 5 x 5 median — Sun, Roth & Black, CVPR 2010); `warps_half` at half
       resolution, 3/4 of the pixels iterated: with the SOR solver 2 there did as well as 3.
    2. Upsample to full resolution (iterating there, three quarters of the pixels, costs 3x the time and
       changed the EPE by < 0.01 px on the tuning scenes).
    3. Final fusion with the dominant affine motion at k = 0.5 (the dense flow must explain the images twice
       as well to beat it: textureless background stays still when small objects move fast), a 5 x 5 median.
    Defaults tuned on synthetic chairs-like scenes and FlyingChairs 0000000 only (benchmarks/ch09_flow.py),
    except the solver (6 red-black SOR sweeps at omega 1.5, 2 warps at half resolution; formerly 20 Jacobi
    sweeps, 3 warps): chosen for speed with all five pairs in view, kept because no pair's EPE got worse."""
    I1, I2 = np.asarray(I1, float), np.asarray(I2, float)
    P1, P2 = gaussian_pyramids(I1, I2, min_size)
    f = np.zeros(P1[-1].shape + (2,), np.float32)
    for L in range(len(P1) - 1, 0, -1):
        if f.shape[:2] != P1[L].shape:
            f = _resize_flow(f, P1[L].shape)
        f = _fuse(P1[L], P2[L], f, affine_motion(f), 1.0).astype(np.float32)
        for _ in range(warps if L > 1 else warps_half):
            f = _robust_warp_step(P1[L], P2[L], f, alpha, rho, eps, tau, sigma, sweeps, omega)
    f = _resize_flow(f, I1.shape)
    A = affine_motion(f)
    keep = _keep(I1, I2, f, A, 0.5)
    # The median of an affine field over a symmetric 5 x 5 window is its centre value: only the windows that
    # hold some of f, and those at the border (replicated, not symmetric), need one.
    border = np.ones(keep.shape, bool)
    border[2:-2, 2:-2] = False
    need = maximum_filter1d(maximum_filter1d(keep, 5, axis=0), 5, axis=1) | border    # a 5 x 5 dilation
    return _median_flow(np.where(keep[..., None], f, A), need).astype(float)
