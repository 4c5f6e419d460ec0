"""Chapter 8 mutants of 8.20 (splatting training diverges), appended to ch08_dense.MUTANTS.

Each refits with the course's reference fit (8.16's `fit_splats`; the grader's bar is its own stand-in fitter)
and gets one thing wrong: the diagnosis, or a repair that turns the wrong knob.
"""
from __future__ import annotations

import numpy as np


def _fit(case, init=None, lr_means=None):
    from solutions.ch08_dense.fit2d import fit_splats
    s = case["settings"]
    return fit_splats(case["target"], case["init"] if init is None else init, s["steps"], s["max_gaussians"],
                      lr_means=s["lr"]["means"] if lr_means is None else lr_means)


def _outside(case) -> bool:
    m, (H, W) = np.asarray(case["init"]["means"]), case["target"].shape[:2]
    return np.mean((m[:, 0] >= 0) & (m[:, 0] < W) & (m[:, 1] >= 0) & (m[:, 1] < H)) < 0.5


def _grid(case) -> dict:
    H, W = case["target"].shape[:2]
    g = (np.arange(3) + 0.5) / 3
    mx, my = np.meshgrid(g * W, g * H)
    return {"means": np.c_[mx.ravel(), my.ravel()], "scales": np.full((9, 2), 3.0), "theta": np.zeros(9),
            "color": np.full((9, 3), 0.5), "opacity": np.full(9, 0.5)}


def diverge_always_lr(case):
    """Blames the learning rate every time; repairs both runs properly (a grid start and 0.3 px per step)."""
    return {"cause": "position_lr", "gaussians": _fit(case, _grid(case), 0.3)}


def diverge_lower_lr_only(case):
    """Reads the log right but only ever lowers the position learning rate, from the colleague's start."""
    return {"cause": "bad_init" if _outside(case) else "position_lr", "gaussians": _fit(case, lr_means=0.3)}


def diverge_reinit_only(case):
    """Reads the log right but only ever re-initialises on a grid, keeping the colleague's learning rate."""
    return {"cause": "bad_init" if _outside(case) else "position_lr", "gaussians": _fit(case, _grid(case))}


def diverge_halved_lr(case):
    """Tries a knob: halves the position learning rate (still 2.5-4 px per step) and re-initialises."""
    return {"cause": "bad_init" if _outside(case) else "position_lr",
            "gaussians": _fit(case, _grid(case), case["settings"]["lr"]["means"] / 2)}


def diverge_unchanged(case):
    """Right cause, the colleague's Gaussians handed back."""
    return {"cause": "bad_init" if _outside(case) else "position_lr", "gaussians": case["gaussians"]}


MUTANTS: list[tuple] = [
    ("8.20", "always blames the learning rate", diverge_always_lr, "where do the Gaussians start?"),
    ("8.20", "lowers the learning rate only", diverge_lower_lr_only, "never reaches the picture"),
    ("8.20", "re-initialises only", diverge_reinit_only, "scatters the Gaussians out of the frame"),
    ("8.20", "halves the learning rate", diverge_halved_lr, "halving a rate"),
    ("8.20", "unchanged", diverge_unchanged, None),
]
