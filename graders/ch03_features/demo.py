"""Notebook-only pictures for chapter 3: the DoG scale space (3.20), the SIFT descriptor grid, the FAST-16
circle (3.21), and the DEBUG cases' detections and matches. Each draws into a new figure and leaves
`plt.show()` to the notebook cell. matplotlib is imported on first use: graders load without it."""
from __future__ import annotations

import cv2
import numpy as np

from graders.kit import scene
from .common import transfer
from .debug_data import correct

# Bresenham circle of radius 3: (dx, dy) of pixels 1..16, clockwise from 12 o'clock (y down), FAST's numbering.
FAST_CIRCLE = np.array([(0, -3), (1, -3), (2, -2), (3, -1), (3, 0), (3, 1), (2, 2), (1, 3),
                        (0, 3), (-1, 3), (-2, 2), (-3, 1), (-3, 0), (-3, -1), (-2, -2), (-1, -3)])


def _mpl():
    import matplotlib.pyplot as plt
    from matplotlib.collections import LineCollection
    from matplotlib.patches import Circle, Rectangle
    return plt, Circle, Rectangle, LineCollection


def show_dog_stack(s: int = 3, sigma0: float = 1.6, octaves: int = 2, size: int = 96):
    """Two octaves of SIFT's scale space on a crop of a texture: the s + 3 Gaussian images of each octave
    (sigma0 k^i, k = 2^(1/s)), the s + 2 DoG images between neighbours, and the 3 x 3 x 3 neighbourhood a
    DoG extremum is compared with (26 neighbours: 8 at its own level, 9 above, 9 below)."""
    from scipy import ndimage
    plt, Circle, Rectangle, LineCollection = _mpl()
    img = scene.texture("astronaut", (2 * size, 2 * size))[size // 2:size // 2 + size, size // 2:size // 2 + size]
    k = 2 ** (1 / s)
    n_g = s + 3
    fig, axes = plt.subplots(2 * octaves, n_g, figsize=(1.45 * n_g, 1.55 * 2 * octaves),
                             layout="none")   # fixed spacing below: a layout engine is slow on 24 axes
    base = ndimage.gaussian_filter(img, np.sqrt(sigma0 ** 2 - 0.5 ** 2))
    for o in range(octaves):
        G = [base]
        for i in range(1, n_g):   # blur each from the previous: sigma_i^2 - sigma_(i-1)^2
            G.append(ndimage.gaussian_filter(G[-1], sigma0 * np.sqrt(k ** (2 * i) - k ** (2 * i - 2))))
        D = [b - a for a, b in zip(G, G[1:])]
        for i, g in enumerate(G):
            ax = axes[2 * o, i]
            ax.imshow(g, cmap="gray", vmin=0, vmax=1)
            ax.set_title(f"o{o} G{i}: σ={sigma0 * k ** i * 2 ** o:.2f}", fontsize=8,
                         color="C3" if i == s else "k")
        for i, d in enumerate(D):
            ax = axes[2 * o + 1, i]
            ax.imshow(d, cmap="RdBu", vmin=-0.08, vmax=0.08)
            searched = 1 <= i <= s
            ax.set_title(f"DoG{i}" + (" (searched)" if searched else ""), fontsize=8, color="C0" if searched else "0.4")
            if o == 0 and i in (1, 2, 3):   # one 3x3x3 block: the same 3x3 window in DoG1, DoG2, DoG3
                cy, cx = size // 2, size // 2
                ax.add_patch(Rectangle((cx - 1.5, cy - 1.5), 3, 3, fill=False, ec="lime", lw=1.5))
        _draw_neighbourhood(axes[2 * o + 1, n_g - 1], o == 0)
        base = G[s][::2, ::2]      # image s (blurred by 2 sigma0) subsampled starts the next octave
    for ax in axes.ravel():
        ax.set(xticks=[], yticks=[])
    fig.suptitle(f"s = {s}, k = 2^(1/{s}): Gaussian images (rows 1, 3), DoG images (rows 2, 4); red: the image "
                 "that, subsampled by 2, starts the next octave", fontsize=8)
    fig.subplots_adjust(left=0.01, right=0.99, bottom=0.01, top=0.9, wspace=0.08, hspace=0.35)  # tight_layout: slow on 24 axes
    return fig


def _draw_neighbourhood(ax, label: bool):
    """The 3 x 3 x 3 block as three stacked 3 x 3 grids (below, own level, above); the centre is compared
    with the 26 others."""
    plt, Circle, Rectangle, LineCollection = _mpl()
    for level, (dx, dy) in enumerate([(0, 0), (1.4, 1.1), (2.8, 2.2)]):
        for i in range(3):
            for j in range(3):
                centre = level == 1 and i == 1 and j == 1
                ax.add_patch(Rectangle((dx + i * 0.55, dy + j * 0.55), 0.5, 0.5, fc="C3" if centre else "0.85",
                                       ec="k", lw=0.5))
        if label:
            ax.text(dx + 1.7, dy + 0.7, ["DoG i-1", "DoG i", "DoG i+1"][level], fontsize=8)
    ax.set(xlim=(-0.2, 5.2), ylim=(-0.2, 4.2), aspect="equal")
    ax.set_title("3×3×3: 26 neighbours", fontsize=8)
    ax.axis("off")


def show_sift_grid(seed: int = 0):
    """SIFT's descriptor on one patch: the 16 x 16 sample window (gradient arrows), its 4 x 4 cells, the
    Gaussian weight (sigma = half the window), and each cell's 8-bin orientation histogram: 4 x 4 x 8 = 128."""
    from scipy import ndimage
    plt, Circle, Rectangle, LineCollection = _mpl()
    img = scene.texture("brick", (64, 64))
    rng = np.random.default_rng(seed)
    y0, x0 = rng.integers(10, 38, 2)
    P = ndimage.gaussian_filter(img, 1.0)[y0:y0 + 16, x0:x0 + 16]
    gy, gx = np.gradient(P)
    yy, xx = np.mgrid[0:16, 0:16] - 7.5
    w = np.exp(-(xx ** 2 + yy ** 2) / (2 * 8.0 ** 2))                  # sigma = half the window width
    mag, ang = np.hypot(gx, gy) * w, np.arctan2(gy, gx) % (2 * np.pi)
    bins = (ang / (2 * np.pi) * 8).astype(int) % 8
    hist = np.zeros((4, 4, 8))
    for cy in range(4):
        for cx in range(4):
            sl = np.s_[4 * cy:4 * cy + 4, 4 * cx:4 * cx + 4]
            hist[cy, cx] = np.bincount(bins[sl].ravel(), mag[sl].ravel(), minlength=8)
    fig, (a, b) = plt.subplots(1, 2, figsize=(9, 4.3))
    a.imshow(P, cmap="gray", extent=(-0.5, 15.5, 15.5, -0.5))
    a.quiver(np.arange(16)[None].repeat(16, 0), np.arange(16)[:, None].repeat(16, 1), gx * w, gy * w,
             color="C1", angles="xy", scale_units="xy", scale=np.hypot(gx * w, gy * w).max() / 1.2)   # longest: 1.2 px
    for t in (3.5, 7.5, 11.5):
        a.axhline(t, color="C0", lw=1)
        a.axvline(t, color="C0", lw=1)
    for r in (8, 16):
        a.add_patch(Circle((7.5, 7.5), r, fill=False, ec="C2", ls="--", lw=1))
    a.set(xlim=(-0.5, 15.5), ylim=(15.5, -0.5), title="16 × 16 samples in 4 × 4 cells; arrows: gradients ×\n"
          "Gaussian weight (σ = 8 samples; dashed: 1σ, 2σ)")
    b.set(xlim=(0, 4), ylim=(4, 0), aspect="equal", xticks=[], yticks=[],
          title="per cell: an 8-bin histogram of gradient angles\n(weighted magnitudes) → 4 · 4 · 8 = 128 numbers")
    scale = 0.45 / hist.max()
    for cy in range(4):
        for cx in range(4):
            b.add_patch(Rectangle((cx, cy), 1, 1, fill=False, ec="C0"))
            for k in range(8):
                t = (k + 0.5) * np.pi / 4
                r = hist[cy, cx, k] * scale
                b.plot([cx + 0.5, cx + 0.5 + r * np.cos(t)], [cy + 0.5, cy + 0.5 + r * np.sin(t)], color="C1", lw=2)
    return fig


def show_fast_circle(pattern: str = "ddsssssbbbbbbbbb"):
    """The FAST-16 circle: a Bresenham circle of radius 3 around p, pixels 1-16 clockwise from 12 o'clock.
    `pattern` labels them b (brighter than I_p + t), d (darker than I_p - t), s (similar); the longest
    contiguous arc (wrapping from 16 to 1) decides: 9 or more of one kind makes p a FAST-9 corner."""
    plt, Circle, Rectangle, LineCollection = _mpl()
    colours = {"b": "#ffe066", "d": "#4c6ef5", "s": "0.8"}
    fig, (a, b) = plt.subplots(1, 2, figsize=(8.4, 4), gridspec_kw={"width_ratios": [1, 1.2]})
    for y in range(-3, 4):
        for x in range(-3, 4):
            a.add_patch(Rectangle((x - 0.5, y - 0.5), 1, 1, fc="white", ec="0.7", lw=0.5))
    for n, ((dx, dy), c) in enumerate(zip(FAST_CIRCLE, pattern)):
        a.add_patch(Rectangle((dx - 0.5, dy - 0.5), 1, 1, fc=colours[c], ec="k", lw=1.5 if n in (0, 4, 8, 12) else 0.5))
        a.text(dx, dy, str(n + 1), ha="center", va="center", fontsize=8)
    a.add_patch(Rectangle((-0.5, -0.5), 1, 1, fc="C3", ec="k"))
    a.text(0, 0, "p", ha="center", va="center", color="w")
    a.set(xlim=(-3.6, 3.6), ylim=(3.6, -3.6), aspect="equal", xticks=[], yticks=[],
          title="radius-3 Bresenham circle, 16 pixels\n(bold: 1, 5, 9, 13: the quick test)")
    run, best = _longest_arc(pattern)
    t = -np.pi / 2 + 2 * np.pi * np.arange(16) / 16              # clockwise from 12 o'clock, y down
    for n, c in enumerate(pattern):
        in_arc = n in run
        b.add_patch(Circle((np.cos(t[n]), np.sin(t[n])), 0.13, fc=colours[c], ec="C3" if in_arc else "k",
                           lw=2.5 if in_arc else 0.5))
        b.text(1.3 * np.cos(t[n]), 1.3 * np.sin(t[n]), str(n + 1), ha="center", va="center", fontsize=8)
    b.set(xlim=(-1.6, 1.6), ylim=(1.6, -1.6), aspect="equal", xticks=[], yticks=[],
          title=f"{pattern}: longest arc {len(run)} × '{best}' (red; it may\nwrap from 16 to 1) → "
                f"{'a corner' if len(run) >= 9 else 'not a corner'} for FAST-9")
    return fig


def _longest_arc(pattern: str) -> tuple[list[int], str]:
    """Indices of the longest run of b or d around the circle (wrapping), and its letter."""
    best: list[int] = []
    letter = "s"
    for c in "bd":
        for start in range(16):
            run = []
            while len(run) < 16 and pattern[(start + len(run)) % 16] == c:
                run.append((start + len(run)) % 16)
            if len(run) > len(best):
                best, letter = run, c
    return best, letter


def shelving(rng: np.random.Generator, size=(640, 480)) -> np.ndarray:
    """Warehouse shelving: a grid of identical bays (uprights, beams, boxes with the same label). A float32
    image in [0, 1], (height, width) = size[::-1]."""
    W, H = size
    img = np.full((H, W), 0.55)
    bay_w, bay_h = int(rng.integers(70, 90)), int(rng.integers(60, 75))
    labels = [(rng.random((10, 16)) > 0.5) * 0.5 + 0.25 for _ in range(3)]  # three products in stock
    for y0 in range(0, H - bay_h + 1, bay_h):
        img[y0:y0 + 6] = 0.15  # beam
        for x0 in range(0, W - bay_w + 1, bay_w):
            img[:, x0:x0 + 5] = 0.2  # upright
            bx, by = x0 + 12, y0 + 18
            img[by:by + 36, bx:bx + 48] = 0.8  # box
            img[by + 10:by + 20, bx + 16:bx + 32] = labels[int(rng.integers(3))]
            img[by + 24:by + 30, bx + 4:bx + 44] = 0.8 - 0.4 * (rng.random((6, 40)) > 0.7)  # barcode
    img += rng.normal(0, 0.01, img.shape)
    return cv2.GaussianBlur(np.clip(img, 0, 1).astype(np.float32), (0, 0), 0.8)


def show_debug_matches(case: dict, matches: np.ndarray, H: np.ndarray, title: str = "", keep=None):
    """Both views' detections side by side (dots sized by response; `keep`: (keep1, keep2) drawn in black), and
    `matches` as lines: green if the true H confirms them within 3 px, red if not."""
    plt, Circle, Rectangle, LineCollection = _mpl()
    W, Hh = case["image_size"]
    fig, ax = plt.subplots(figsize=(10, 3.9))
    for v, off in ((1, 0), (2, W + 20)):
        kp, r = case[f"kp{v}"], case[f"resp{v}"]
        ax.scatter(kp[:, 0] + off, kp[:, 1], s=2 + 6 * r / r.max(), c="0.7", lw=0)
        if keep is not None:
            k = keep[v - 1]
            ax.scatter(kp[k, 0] + off, kp[k, 1], s=6, c="k", lw=0)
        ax.add_patch(Rectangle((off - 0.5, -0.5), W, Hh, fill=False, ec="0.3"))
    m = np.asarray(matches, int).reshape(-1, 2)
    ok = correct({"H": H, "kp1": case["kp1"], "kp2": case["kp2"]}, m)
    seg = np.stack([case["kp1"][m[:, 0]], case["kp2"][m[:, 1]] + [W + 20, 0]], axis=1)
    ax.add_collection(LineCollection(seg, colors=np.where(ok[:, None], [[0, 0.7, 0]], [[0.9, 0, 0]]), lw=0.6))
    ax.set(xlim=(-10, 2 * W + 30), ylim=(Hh + 10, -10), aspect="equal", xticks=[], yticks=[],
           title=title or f"{len(m)} matches, {ok.sum()} correct (green) under the true homography")
    return fig


def view2_outline(H: np.ndarray, size) -> np.ndarray:
    """View 2's border mapped into view 1 (5, 2): what view 1's part of the scene view 2 sees."""
    W, Hh = size
    c = np.array([[0, 0], [W - 1, 0], [W - 1, Hh - 1], [0, Hh - 1], [0, 0]], float)
    return transfer(np.linalg.inv(H), c)
