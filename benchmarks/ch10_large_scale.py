"""Chapter 10: large-scale retrieval and Sim(3) merging against brute force and pycolmap, side by side.

- retrieval: the from-scratch vocabulary tree (`solutions.ch10_large_scale.vocab_tree_retrieve`) vs
  brute-force descriptor matching of every query against every database image, on textured-plane
  renders of known places, at growing database sizes: mAP, recall@5, query time, and how each grows with N.
- merge: the from-scratch Sim(3) RANSAC + merge vs pycolmap.estimate_sim3d_robust on the same shared
  points: scale / rotation / translation error against the truth and time.
- part B adds the Dask pipeline's throughput (1 and 2 workers against the serial run).
"""
from __future__ import annotations

from benchmarks.timing import median_time, table  # noqa: F401 (used by the sections below)


def retrieval() -> list[dict]:
    print("retrieval: not built yet")
    return []


def merge() -> list[dict]:
    print("merge: not built yet")
    return []


# part B: def distributed() -> list[dict]: ... (and add it to SECTIONS)
SECTIONS = [retrieval, merge]


def run() -> list[dict]:
    rows: list[dict] = []
    for section in SECTIONS:
        rows += section()
    return rows


if __name__ == "__main__":
    run()
