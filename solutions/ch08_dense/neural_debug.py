"""8.21 (DEBUG) from scratch: blurry splatting renders."""
from __future__ import annotations

from .fit2d import fit_splats

__all__ = ["fix_blurry_splats"]


def fix_blurry_splats(case: dict) -> dict:
    """Exercise 8.21: the log shows the count stuck at the initial 9 Gaussians while the loss is flat — the
    run never densifies, so a few wide Gaussians average every edge away. Refit with densification on
    (split / clone by the accumulated position gradient), the same steps and budget."""
    s = case["settings"]
    return {"cause": "no_densification",
            "gaussians": fit_splats(case["target"], case["init"], s["steps"], s["max_gaussians"])}
