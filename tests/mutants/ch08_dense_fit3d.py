"""Chapter 8 mutants of 8.25 (the FRONTIER 3D Gaussian fit), appended to ch08_dense.MUTANTS.

The course's reference fit (solutions/ch08_dense/fit3d.py, through the reference 8.14 and 8.15) with one step
switched off; the grader judges against renders of its synthetic ground truth, never against a fit of its own.
"""
from __future__ import annotations

import numpy as np


def _fit(*a, **kw):
    from solutions.ch08_dense.fit3d import fit_gaussians_3d
    return fit_gaussians_3d(*a, **kw)


def fit3d_no_densify(views, init, steps=100, max_gaussians=72):
    return _fit(views, init, steps, max_gaussians, densify_until=-1)


def fit3d_no_prune(views, init, steps=100, max_gaussians=72):
    return _fit(views, init, steps, max_gaussians, o_min=0.0)


def fit3d_no_budget(views, init, steps=100, max_gaussians=72):
    """Densifies every 10 steps and forgets the cap."""
    return _fit(views, init, steps, 10 ** 6, every=10)


def fit3d_colours_only(views, init, steps=100, max_gaussians=72):
    """Fits the training views' colours and opacities with frozen positions, rotations and scales."""
    return _fit(views, init, steps, max_gaussians, lr_mu=0.0, lr_shape=0.0)


def fit3d_frozen_means(views, init, steps=100, max_gaussians=72):
    """Fits rotations, scales, colours and opacities, densifying and pruning, but never updates the means: at 24 px
    the reshaped Gaussians still render the held-out views above the PSNR bar on most seeds."""
    return _fit(views, init, steps, max_gaussians, lr_mu=0.0)


def fit3d_untrained(views, init, steps=100, max_gaussians=72):
    """Returns the SfM initialisation with the strays dropped: no optimisation at all."""
    keep = np.asarray(init["opacity"]) >= 0.005
    return {k: np.asarray(v)[keep] for k, v in init.items()}


def fit3d_no_densify_padded(views, init, steps=100, max_gaussians=72):
    """No densification, trained 200 steps instead of the 100 asked (its held-out views then reach the PSNR and depth
    bars on most scenes), plus one near-transparent copy (o = 0.006, above the pruning threshold) appended so the
    output holds more Gaussians than the start. Full marks on 5 of seeds 0-5 while the densified row counted every
    Gaussian; caught since it counts only those that draw (DRAWS in graders/ch08_dense/fit3d.py)."""
    g = _fit(views, init, 200, max_gaussians, densify_until=-1)
    g = {k: np.asarray(v.detach() if hasattr(v, "detach") else v, float) for k, v in g.items()}
    extra = {k: v[:1].copy() for k, v in g.items()}
    extra["opacity"] = np.array([0.006])
    return {k: np.concatenate([g[k], extra[k]]) for k in g}


def fit3d_no_densify_split_after(views, init, steps=100, max_gaussians=72):
    """No densification, trained 300 steps instead of the 100 asked, then its most opaque Gaussian split into two
    copies at the same place, each of opacity 1 - sqrt(1 - o), that together draw what it drew: the output holds one
    more Gaussian that draws than the start. 3/3 on 5 of seeds 0-5 (held-out 26.2-29.2 dB) until the judge compared
    the fit with the same code's run with no room to densify (GAIN_DB in graders/ch08_dense/fit3d.py): both runs are
    the same fit, a gain of 0.00 dB."""
    g = _fit(views, init, 300, max_gaussians, densify_until=-1)
    g = {k: np.asarray(v, float) for k, v in g.items()}
    i = int(np.argmax(g["opacity"]))
    g["opacity"][i] = 1 - np.sqrt(1 - g["opacity"][i])
    return {k: np.concatenate([v, v[i:i + 1]]) for k, v in g.items()}


def _split_all(g, max_gaussians):
    """Every Gaussian split once, in index order within the budget: copies at ±1σ along the longest axis, 1.6×
    smaller (the notebook's split, with no gradient deciding which)."""
    from scipy.spatial.transform import Rotation
    n = max(0, min(len(g["mu"]), max_gaussians - len(g["mu"])))
    i = np.arange(n)
    axis = Rotation.from_quat(g["q"][i][:, [1, 2, 3, 0]]).as_matrix()[i, :, np.argmax(g["s"][i], 1)]
    offset = axis * g["s"][i].max(1)[:, None]
    out = {k: np.concatenate([v, v[i]]) for k, v in g.items()}
    out["mu"][i] -= offset
    out["mu"][len(g["mu"]):] += offset
    out["s"][i] /= 1.6
    out["s"][len(g["mu"]):] /= 1.6
    return out


def fit3d_split_all_then_finetune(views, init, steps=100, max_gaussians=72):
    """No densification during training; then every Gaussian split once (within the budget, in index order) and the
    result fine-tuned for half the steps again. 3/3 on 6 of seeds 0-5 (its gain over the no-room run passes) until
    the judge's selection probe (PROBE_* in graders/ch08_dense/fit3d.py): with room for one more Gaussian it splits
    an exact disc, not the panel's Gaussian."""
    g = {k: np.asarray(v, float) for k, v in _fit(views, init, steps, max_gaussians, densify_until=-1).items()}
    g = _split_all(g, max_gaussians)
    return _fit(views, g, steps // 2, max_gaussians, densify_until=-1)


def fit3d_sandbag_no_room(views, init, steps=100, max_gaussians=72):
    """No densification, 300 steps, its most opaque Gaussian split in place afterwards; and when there is no room to
    densify (max_gaussians ≤ the start's count, the judge's second call) it trains a fifth of the steps, so the
    'densification pays' row sees a gain. 3/3 on 5 of seeds 0-5 until the selection probe (room for one more: its
    copy is a disc's or sits on the panel's Gaussian)."""
    n = int(np.sum(np.asarray(init["opacity"]) >= 0.005))
    if max_gaussians <= n:
        return _fit(views, init, steps // 5, max_gaussians, densify_until=-1)
    g = {k: np.asarray(v, float) for k, v in _fit(views, init, 300, max_gaussians, densify_until=-1).items()}
    i = int(np.argmax(g["opacity"]))
    g["opacity"][i] = 1 - np.sqrt(1 - g["opacity"][i])
    return {k: np.concatenate([v, v[i:i + 1]]) for k, v in g.items()}


MUTANTS: list[tuple] = [
    ("8.25", "no densification", fit3d_no_densify, "no more than the"),
    ("8.25", "no pruning", fit3d_no_prune, "prune them"),
    ("8.25", "no budget", fit3d_no_budget, "cap densification"),
    ("8.25", "colours only, frozen positions", fit3d_colours_only, "not fitted either"),
    ("8.25", "frozen means", fit3d_frozen_means, "depth is off"),
    ("8.25", "untrained", fit3d_untrained, "not fitted either"),
    ("8.25", "no densification, trained longer, one transparent Gaussian appended", fit3d_no_densify_padded,
     "no more than the"),
    ("8.25", "no densification, trained longer, one Gaussian split afterwards", fit3d_no_densify_split_after,
     "densification did not run"),
    ("8.25", "no densification during training, every Gaussian split once afterwards, fine-tuned",
     fit3d_split_all_then_finetune, "did not follow the gradient"),
    ("8.25", "no densification, split afterwards, the no-room run trained a fifth as long", fit3d_sandbag_no_room,
     "did not follow the gradient"),
]
