"""What the course home notebook (notebooks/00_start_here.ipynb) shows: the course map, the pipeline with
its tensor shapes, the learner's progress as a picture, and the lesson's reference tables.

Everything is read from the chapter table (`graders.core.chapters`), the progress file (`graders.study.progress`)
and the reference tables (`graders.study.reference`): a chapter that lands later appears without a change here,
except its row in NEEDS (what to read first), which is data.
"""
from __future__ import annotations

import math

from graders.core.chapters import CHAPTERS, READY
from graders.core.engine import KINDS

# chapter -> chapters to have done first (the course map's "needs" column)
NEEDS: dict[int, tuple[int, ...]] = {1: (), 2: (1,), 3: (), 4: (1, 2, 3), 5: (4,), 6: (2, 5), 7: (1, 5), 8: (1, 4),
                                     9: (3,), 10: (4, 5, 6), 11: (1, 2, 3, 4, 5, 6, 7)}

# The pipeline from photons to map, one stage a row: (stage, chapter, what flows out, its shape).
PIPELINE: tuple[tuple[str, int, str, str], ...] = (
    ("calibrated camera", 1, "K, distortion, extrinsics", "K (3, 3), dist (5,), T_cam_rig (4, 4)"),
    ("image", 1, "8-bit RGB frame, undistorted", "(H, W, 3) uint8; 6 × 1280×960 at 30 fps ≈ 660 MB/s"),
    ("features", 3, "keypoints and descriptors", "(N, 2) float px, (N, 256) float or (N, 32) uint8"),
    ("matches", 3, "index pairs after the ratio test", "(M, 2) int"),
    ("two-view geometry", 2, "E or F, inlier mask, relative pose", "(3, 3), (M,) bool, R (3, 3), t (3,)"),
    ("structure", 4, "triangulated points, registered cameras (PnP)", "(P, 3), poses (C, 4, 4)"),
    ("refinement", 5, "bundle-adjusted cameras and points", "BAL cameras (C, 9), points (P, 3)"),
    ("tracking / SLAM", 6, "one pose per frame, keyframes, loop closures", "(T, 4, 4) SE(3), pose graph"),
    ("dense", 8, "depth maps, fused points, Gaussians", "(H, W) float, (Q, 3), 3DGS params (G, 59)"),
    ("motion", 9, "optical flow, point tracks", "(H, W, 2) float, (T, K, 2) + visibility (T, K)"),
    ("map at scale", 10, "merged sub-maps, retrieval index", "Sim(3) per sub-map, 50K-500K landmarks"),
)


def course_map() -> str:
    """The chapters as a markdown table: number, title, status, what to do first, what it covers."""
    rows = ["| # | chapter | status | do first | covers |", "|---|---|---|---|---|"]
    for ch in CHAPTERS:
        needs = ", ".join(str(n) for n in NEEDS.get(ch.number, ())) or "—"
        here = ch in READY        # a student edition holds some of the ready chapters
        status = "ready" if here else "not in this edition" if ch.ready else "planned"
        link = f"[{ch.title}]({ch.notebook.split('/')[-1]})" if here else ch.title
        rows.append(f"| {ch.number} | {link} | {status} | {needs} | {ch.summary or '—'} |")
    return "\n".join(rows)


def pipeline_table() -> str:
    rows = ["| stage | chapter | what flows out | shape |", "|---|---|---|---|"]
    rows += [f"| {s} | {c} | {what} | {shape} |" for s, c, what, shape in PIPELINE]
    return "\n".join(rows)


def progress_grid(events: list[dict] | None = None, totals: dict | None = None):
    """(chapter keys, kinds, fraction of points earned (chapters × kinds, NaN where a chapter has none))."""
    from graders.study.progress import read, summary
    rows = summary(read() if events is None else events)
    chapters = [c.key for c in READY]
    grid = []
    for ch in chapters:
        line = []
        for kind in KINDS:
            n, pts = (totals or {}).get((ch, kind), (0, 0.0))
            got = rows.get((ch, kind), {}).get("points", 0.0)
            line.append(got / pts if pts else (math.nan if totals is not None else got))
        grid.append(line)
    return chapters, list(KINDS), grid


def plot_progress(ax=None, events: list[dict] | None = None, totals: dict | None = None):
    """A heat map of points earned per chapter and dimension (grey: no exercise of that kind)."""
    import matplotlib.pyplot as plt
    import numpy as np
    chapters, kinds, grid = progress_grid(events, totals)
    data = np.ma.masked_invalid(np.array(grid, float).T)
    if ax is None:
        _, ax = plt.subplots(figsize=(1 + 0.6 * len(chapters), 3))
    cmap = plt.get_cmap("Greens").with_extremes(bad="0.9")
    im = ax.imshow(data, cmap=cmap, vmin=0, vmax=1, aspect="auto")
    ax.set_xticks(range(len(chapters)), [f"ch {c}" for c in chapters])
    ax.set_yticks(range(len(kinds)), [k.upper() for k in kinds])
    for (k, c), value in np.ndenumerate(data.filled(np.nan)):
        if np.isfinite(value) and value > 0:
            ax.text(c, k, f"{value:.0%}", ha="center", va="center", fontsize=8,
                    color="white" if value > 0.6 else "black")   # readable on the dark greens
    if not np.any(data.filled(0) > 0):      # say why the picture is empty instead of showing a blank grid
        ax.text(0.5, 0.5, "no points yet: run a check(...) in any chapter, or a drill", transform=ax.transAxes,
                ha="center", va="center", fontsize=11, bbox={"facecolor": "white", "edgecolor": "0.6"})
    ax.set_xlabel("chapter"); ax.set_ylabel("dimension")
    ax.set_title("your points per chapter and dimension")
    ax.figure.colorbar(im, ax=ax, fraction=0.03, label="fraction of the points earned")
    return ax


def progress_details(totals: dict | None = None) -> str:
    """The progress table as HTML, folded under a <details> toggle (the figure above is the summary), with
    where the file is and how to start afresh."""
    import html
    from graders.study.progress import progress_file, table
    path = html.escape(str(progress_file()))
    return (f"<details><summary>The table behind the picture: attempts, passes and points per chapter and "
            f"dimension (click to open)</summary><pre>{html.escape(table(totals=totals))}</pre></details>"
            f"<p>Your progress file: <code>{path}</code> (one line per check or drill; <code>python -m graders progress "
            f"--where</code> prints it). To start afresh, move or delete that file; to keep separate records, "
            f"set <code>CV3D_PROGRESS</code> to another folder before starting JupyterLab.</p>")


def reference_markdown(key: str) -> str:
    """One of the reference tables, readable. Cells the chapters refute are shown corrected, with a note of the
    figure they replace and why ("not “…”: why (where)"); the RANSAC counts and times are the formula's own values
    (the learner never sees the transcribed source, so it is not cited to them)."""
    from graders.study.reference import TABLES, corrected_row, ransac_iterations
    t = TABLES[key]
    header, rows, notes = list(t.header), [], []
    for i in range(len(t.rows)):     # cells the chapters refute are shown corrected, the quoted cell in a note
        row, fixes = corrected_row(key, i)
        rows.append(list(row))
        for j, note in fixes.items():
            notes.append(note)
            rows[-1][j] += f" [{len(notes)}]"
    title = f"**{t.title}**"
    if key == "ransac":
        header = ["Inlier ratio w", "5-point (s=5)", "8-point (s=8)", "8-point time @ 1 ms/iter"]
        for r in rows:
            w = float(r[0].rstrip("%")) / 100
            k5, k8 = ransac_iterations(w, 5), ransac_iterations(w, 8)
            r[1:] = [f"{k5:,}", f"{k8:,}", f"{k8 * 1e-3:.3g} s"]
        title += (" — k = ⌈log(1 − p) / log(1 − wˢ)⌉ with p = 0.99 (Fischler & Bolles, CACM 1981; Hartley & "
                  "Zisserman, 2nd ed., §4.7.1). Tables quoted in many tutorials differ from these values.")
    out = [title, "", "| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    out += ["| " + " | ".join(c.replace("|", "\\|") for c in r) + " |" for r in rows]
    if notes:
        out += [""] + [f"[{k}] Corrected: {note}." for k, note in enumerate(notes, 1)]
    return "\n".join(out)
