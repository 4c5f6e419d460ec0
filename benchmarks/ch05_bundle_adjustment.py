"""Chapter 5: the from-scratch bundle adjuster (solutions.ch05_bundle_adjustment.bundle_adjust) against
Ceres (through pycolmap) on two BAL-format problems, and the SciPy cookbook's least_squares on the first.

Problems
- BAL problem-49-7776-pre (Ladybug; $COURSE_DATA/bal): 49 cameras, 7,776 points, 31,843 observations.
- street-300: a synthetic BAL problem made by `street_problem(seed=7)` (below), written to a BAL text
  file and read back with the chapter's `read_bal`: 300 cameras 1 m apart along a street, looking
  sideways at a facade 8-20 m away; 50,000 points, each tracked over 2-8 consecutive cameras that see
  it; BAL cameras (f 500-700 px, k1, k2 small); Gaussian pixel noise sigma = 0.5 px, NO outliers (plain
  least squares is then the right cost for both solvers); the start: the truth perturbed.
  Why no outliers: with 1 % of them (uniform pixels >= 20 px off, `street_problem(outliers=0.01)`) the cost
  column compares nothing. Under plain L2 Ceres' BAL cost ends at 8e40; under Huber with the same scale in
  both solvers (2 px; pycolmap 4.2.1 exposes it: BundleAdjustmentOptions.ceres.loss_function_type = HUBER,
  .loss_function_scale) Ceres' BAL cost still ends at 3e28 with 183 observations behind their camera: an
  outlier on a point seen twice cannot be told from the point's depth, so the point may cross behind a
  camera, where COLMAP drops the observation (zero residual) while the BAL formula keeps it.

Solvers, each stopped the same way
- reference: Levenberg-Marquardt with Marquardt's diagonal and Nielsen's damping update (Ceres'
  default LEVENBERG_MARQUARDT trust region does the same: radius 1e4 = 1 / lambda0, success
  radius /= max(1/3, 1 - (2 rho - 1)^3), failure radius /= v, v *= 2), Schur complement,
  reduced camera system by dense Cholesky up to 50 cameras and SuperLU beyond (COLMAP's
  choice: DENSE_SCHUR up to 50 images, SPARSE_SCHUR up to 1,000). The observations are sorted by
  camera once; S's upper-triangle blocks are assembled one BLAS product per camera pair over the
  observation pairs behind it (the pairs listed once per adjustment, gathered 4,096 at a time), the
  diagonal blocks and U, g_c one product per camera over its contiguous run. Two rows: one thread,
  and `threads=2` (projections, Jacobians and per-observation blocks on two halves of the
  observations, W V^-1 W^T's chunks shared, in a pool of two Python threads: numpy releases the GIL).
- Ceres through `pycolmap.create_default_bundle_adjuster(...).solve()`, gauge fixed as
  `pycolmap.bundle_adjustment` does (TWO_CAMS_FROM_WORLD), RADIAL cameras, principal point fixed.
Tolerances, the same definitions in both (Ceres 2.2, internal/ceres/trust_region_minimizer.cc):
function tolerance 1e-6: stop once a step changes the cost by |dF| <= 1e-6 * F (F the cost before
the step); gradient tolerance 1e-10 on the largest gradient entry; parameter tolerance 1e-8: stop
once |dx| <= 1e-8 (|x| + 1e-8); at most 50 iterations. (Ceres also stops on a rejected step whose
|dF| is that small; the reference only on accepted ones.)

Timing: the solvers take turns (benchmarks.timing.taking_turns: a warm-up, then `repeat` rounds),
so a load spike on the shared machine falls on all of them; medians of wall and process CPU time
(all threads: Ceres runs 2). The reference's time includes everything it does; Ceres' includes
building the COLMAP reconstruction and reading it back, and the column "Ceres solve" gives its own
summary.total_time_in_seconds. Everything runs in one child process whose BLAS has one thread (a
multithreaded OpenBLAS spins on a busy 2-core machine: a 441 x 441 Cholesky then costs 10x the CPU);
Ceres keeps its own 2 threads. The load average is printed before and after.
`--before DIR`: also time the reference as it is in DIR (a checkout of an older commit).
Final costs: 0.5 sum |r|^2 over ALL observations with the BAL formula (COLMAP drops observations
behind a camera: 31 of BAL-49's).

Measured 2026-12-05 on the shared 2-core machine, CPU time the fair column (process time, all threads):
  Earlier (before 11d4d3d, commit a44ceac as `--before`): BAL-49 CPU s 7.11 / 5.65 (1.41x Ceres' 4.00), costs
  1.33443e4 vs Ceres' 1.33712e4; street-300 then had 1 % outliers and its cost column was void (see above).
  Before this round (d5ac15b, street-300 already without outliers; load 56 -> 13 -> 31):
    BAL-49, 3 rounds: reference 5.44 CPU s (1.44x Ceres' 3.77), wall 19.5 (Ceres 15.8, its solve 10.8);
    street-300, 1 round: reference 12.03 CPU s (0.45x Ceres' 26.69), 10 steps vs Ceres' 40, both at 2.74539e4.
  Then (11d4d3d + docstrings, `--before` = d5ac15b; load 9.5 at the start, 9.3 between, 14.2 at the end,
  with chapter 5's fairness sweep running beside it):
    BAL-49, 3 rounds: before 6.83 CPU s (1.59x; its default solver is SuperLU), now 4.90 (1.14x), Ceres 4.29;
      costs 1.33443e4 (32 steps) vs Ceres' 1.33712e4 (31 steps); scipy cookbook 39.4 CPU s, 1.34089e4.
    street-300, 1 round: before 14.20 CPU s (0.51x), now 10.50 (0.38x), Ceres 27.99 (40 steps);
      final costs 27453.91 (reference, 10 steps) vs 27453.94 (Ceres).
  Wall times this round are void for Ceres: under nice 19 on the loaded machine its 2 threads waited
  (street-300: 241 s wall for 28 s CPU), so the printed "goal met" on wall says nothing; compare CPU.
This round (issue 32; 7d0e887 and 8e9b107, `--before` = 27b5532, the state above; the machine at load
16-19 from other jobs, everything under nice 19, so each process got ~12-14 % of a core and wall times
are ~7x CPU times; Ceres' two threads get two shares of that, as do the reference's with threads=2):
  run 1 (7d0e887, all rows; load 16.0 at the start, 19.1 between, BAL-49 3 rounds, street-300 1 round):
    BAL-49: before 4.43 CPU s (1.22x Ceres' 3.64), wall 1.88x Ceres' solve (17.75 s); one thread 3.01 s
      (0.83x), wall 1.18x; two threads 3.07 s (0.84x), wall 1.07x; costs 1.33443e4 (0.9980x Ceres'),
      32 steps vs 31; scipy cookbook 36.36 CPU s (9.99x), 1.34089e4.
    street-300: before 8.57 CPU s (0.35x Ceres' 24.80), wall 0.62x Ceres' solve; one thread 5.91 (0.24x),
      wall 0.42x; two threads 5.81 (0.23x), wall 0.35x; all at 2.74539e4 (1.0000x), 10 steps vs 40.
  run 2 (8e9b107: threads=2 also splits V_k, W_k, V^-1 W^T and the back-substitution; BAL-49 only, no
    scipy, 3 rounds; load 17.6 -> 19.2): before 4.59 CPU s (1.29x Ceres' 3.55), wall 1.77x Ceres'
    solve (21.71 s); one thread 2.93 (0.82x), wall 1.23x; two threads 3.23 (0.91x), wall 0.90x.
Goal (time <= Ceres' at a cost <= Ceres'): street-300 met with one thread and two. BAL-49: CPU met
(0.82x with one thread); wall met with two threads in run 2 (0.90x Ceres' solve time, 0.82x its total wall),
not with one (1.18-1.23x), and run 1's two-thread figure (1.07x, before 8e9b107) missed it: on this
loaded machine the wall ratio mostly counts how many runnable threads each solver has, so read it
beside the CPU column. Where the one-thread time went (BAL-49, 7d0e887, cProfile with a process-time
clock, ~95 ms an iteration): the Jacobians ~23 ms, W V^-1 W^T ~30 ms (gathers now ~7 ms of it: the
pairs k = l need none, the rest are gathered in cache-sized chunks), the rest of the Schur solve ~16 ms
(V_j^-1 W_k^T alone ~8 ms), the normal equations ~17 ms. Not tried: block-Jacobi PCG on the implicit S
(Ceres' ITERATIVE_SCHUR; one implicit product S x costs 6.8 ms in numpy on BAL-49, so ~7 CG iterations
would eat the assembly it saves) and torch.
Round 4 (issue 32; f3028e1, `--before` = 3bf82bf, whose row runs its default SuperLU, so the dense-vs-dense
before/after comes from a separate harness: both packages in one process with one BLAS thread, taking turns,
8 rounds, load 12-17): dense Schur 1.60 -> 1.51 CPU s (median; 0.94x), same 32 steps, cost equal to 1e-12.
cProfile (process-time clock) before it: ~60 ms an iteration, of which the Jacobians ~16 ms (J_pt as
broadcast column-times-row sums ~3 ms), the per-observation V_k, W_k^T ~5 ms, and schur_solve's own lines
~6 ms (W V^-1 g_p from strided column products of W^T). Now: J_pt = du/dP R and V_k, W_k^T = (w J_pt)^T
[J_pt, J_cam] as batched matmuls on a contiguous (w J_pt)^T, W V^-1 g_p and g_p as einsums; schur_solve's own
lines ~1 ms. BAL-49, this benchmark, 5 rounds: run 1 (load 15.4 -> 13.8, chapter 5's fairness beside it):
one thread 1.58 CPU s (0.99x Ceres' 1.60), two threads 1.73 (1.08x), before 2.21 (SuperLU); run 2 (load
12.3 -> 10.0): one thread 1.56 (1.01x Ceres' 1.54), two threads 1.78 (1.15x). Costs 1.33443e4 (0.9980x
Ceres'), 32 steps vs 31. So the one-thread reference is now level with Ceres in CPU (0.99-1.01x), not clearly
below it. Left: W V^-1 W^T's per-block Python loop (~1,000 blocks an iteration; writing each product with
matmul(out=) instead of += saves ~0.5 ms of its ~8); the Jacobian's strided J_cam column writes (~4 ms).
"""
from __future__ import annotations

import argparse
import os
import time

import numpy as np

from benchmarks.timing import table

FTOL, GTOL, XTOL, MAX_ITER = 1e-6, 1e-10, 1e-8, 50
GOALS = {"time vs Ceres": 1.0, "cost vs Ceres": 1.0}
COLUMNS = ["problem", "solver", "final cost", "cost / Ceres", "accepted steps", "wall s", "CPU s", "wall / Ceres solve",
           "CPU / Ceres CPU"]


def street_problem(seed: int = 7, n_cams: int = 300, n_points: int = 50_000, noise_px: float = 0.5,
                   outliers: float = 0.0, size: tuple[int, int] = (1024, 768)) -> dict:
    """A synthetic street survey in BAL form (see the module docstring); deterministic in `seed`.

    Cameras (OpenCV convention, then BAL's via F = diag(1, -1, -1)) at x = 0, 1, ..., n_cams - 1 m,
    y ~ N(0, 0.2), height 1.5 m, looking along +y with ~3 deg of random rotation. Points: x uniform
    over the street (+-10 m), y in [8, 20] m, z in [0, 12] m. A point's track: from the cameras within
    22 m that see it in front of them and inside the image, 2 + Poisson(2) consecutive ones (capped
    at what is visible) starting at a random one; points seen fewer than twice are dropped.
    Start: rotations x N(0, 0.2 deg), centres + N(0, 5 cm), f x (1 + N(0, 0.5 %)), k1, k2 + N(0, 0.01),
    points + N(0, 10 cm). Returns dict(cameras, points, cam_idx, pt_idx, obs) (the start)."""
    from scipy.spatial.transform import Rotation

    from graders.kit import scene
    from solutions.ch05_bundle_adjustment import bal_project, rotate

    rng = np.random.default_rng(seed)
    w, h = size
    F = np.diag([1.0, -1.0, -1.0])
    base = np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]])   # camera x = world x, y = -z (down), z = +y
    R_cv = Rotation.from_rotvec(rng.normal(0, np.radians(3), (n_cams, 3))).as_matrix() @ base
    C = np.c_[np.arange(n_cams, dtype=float), rng.normal(0, 0.2, n_cams), 1.5 + rng.normal(0, 0.05, n_cams)]
    t_cv = -np.einsum("nij,nj->ni", R_cv, C)
    cams = np.c_[Rotation.from_matrix(F @ R_cv).as_rotvec(), t_cv @ F, rng.uniform(500, 700, n_cams),
                 rng.uniform(-0.1, 0.0, n_cams), rng.uniform(0.0, 0.02, n_cams)]
    n_draw = int(1.4 * n_points)
    X = np.c_[rng.uniform(-10, n_cams + 10, n_draw), rng.uniform(8, 20, n_draw), rng.uniform(0, 12, n_draw)]
    offsets = np.arange(-22, 23)                  # a facade point 20 m away is within 22 m of the cameras seeing it
    cand = np.floor(X[:, :1]).astype(int) + offsets                       # (n_draw, 45) camera candidates
    valid = (cand >= 0) & (cand < n_cams)
    ci_all, pi_all = np.clip(cand, 0, n_cams - 1).ravel(), np.repeat(np.arange(n_draw), len(offsets))
    P = rotate(cams[ci_all, :3], X[pi_all]) + cams[ci_all, 3:6]
    p = -P[:, :2] / P[:, 2:]
    r2 = np.sum(p * p, axis=1)
    uv = (cams[ci_all, 6] * (1 + r2 * (cams[ci_all, 7] + cams[ci_all, 8] * r2)))[:, None] * p   # BAL's projection
    seen = valid.ravel() & (P[:, 2] < 0) & (np.abs(uv[:, 0]) < w / 2) & (np.abs(uv[:, 1]) < h / 2)   # looks down -z
    seen = seen.reshape(n_draw, -1)
    n_seen = seen.sum(axis=1)
    rank = np.cumsum(seen, axis=1) - 1                                       # order of each visible camera
    first = np.floor(rng.uniform(size=n_draw) * np.maximum(n_seen - 1, 1)).astype(int)
    length = 2 + rng.poisson(2.0, n_draw)
    track = seen & (rank >= first[:, None]) & (rank < (first + length)[:, None])
    points = np.flatnonzero(track.sum(axis=1) >= 2)[:n_points]
    if len(points) < n_points:
        raise RuntimeError("street_problem: too few points seen twice")
    pt_idx, cam_pos = np.nonzero(track[points])
    cam_idx = cand[points][pt_idx, cam_pos]
    X = X[points]
    obs = scene.add_noise(rng, bal_project(cams, X, cam_idx, pt_idx), noise_px)
    moved, _ = scene.add_outliers(rng, obs + [w / 2, h / 2], outliers, w, h, min_offset=20.0)
    start = cams.copy()
    rot = Rotation.from_rotvec(rng.normal(0, np.radians(0.2), (n_cams, 3))) * Rotation.from_rotvec(cams[:, :3])
    centres = C + rng.normal(0, 0.05, C.shape)
    start[:, :3] = rot.as_rotvec()
    start[:, 3:6] = -rot.apply(centres)
    start[:, 6] *= 1 + rng.normal(0, 0.005, n_cams)
    start[:, 7:9] += rng.normal(0, 0.01, (n_cams, 2))
    return {"cameras": start, "points": X + rng.normal(0, 0.1, X.shape), "cam_idx": cam_idx, "pt_idx": pt_idx,
            "obs": moved - [w / 2, h / 2]}


def write_bal(path: str, cameras, points, cam_idx, pt_idx, obs) -> None:
    """Write a BAL text file: header `nc np M`, M lines `camera point u v`, then the camera and point numbers."""
    with open(path, "w") as f:
        f.write(f"{len(cameras)} {len(points)} {len(obs)}\n")
        np.savetxt(f, np.c_[cam_idx, pt_idx, obs], fmt=["%d", "%d", "%.10e", "%.10e"])
        np.savetxt(f, np.r_[np.ravel(cameras), np.ravel(points)], fmt="%.16e")


def _problems(which: str = "bal,street") -> dict:
    """name -> (cameras, points, cam_idx, pt_idx, obs) of the problems named in `which` ('bal', 'street';
    BAL-49 only if its data is there)."""
    import tempfile

    from graders import ch05_bundle_adjustment as ch5
    from graders.kit import datasets
    from solutions.ch05_bundle_adjustment import read_bal

    out = {}
    if "bal" not in which:
        pass
    elif datasets.available("bal"):
        p = ch5.load_bal_problem()
        out["BAL problem-49-7776-pre"] = tuple(p[k] for k in ("cameras", "points", "cam_idx", "pt_idx", "obs"))
    else:
        print("BAL data not available: python -m graders.datasets fetch bal (or set COURSE_DATA)")
    if "street" not in which:
        return out
    with tempfile.TemporaryDirectory() as tmp:
        path = os.path.join(tmp, "street-300.txt")
        write_bal(path, *(street_problem()[k] for k in ("cameras", "points", "cam_idx", "pt_idx", "obs")))
        out["street-300 (synthetic, seed 7)"] = read_bal(path)
    return out


def _package_from(tree: str, alias: str):
    """solutions.ch05_bundle_adjustment as it is in the checkout `tree`, imported under `alias`."""
    import importlib.util
    import sys

    folder = os.path.join(tree, "solutions", "ch05_bundle_adjustment")
    spec = importlib.util.spec_from_file_location(alias, os.path.join(folder, "__init__.py"),
                                                  submodule_search_locations=[folder])
    module = importlib.util.module_from_spec(spec)
    sys.modules[alias] = module
    spec.loader.exec_module(module)
    return module


def _methods(args: tuple, before_tree: str | None, ceres_solve: list) -> dict:
    """name -> callable returning (cameras, points, accepted steps) for one problem."""
    from graders import ch05_bundle_adjustment as ch5
    from solutions import ch05_bundle_adjustment as ba

    solver = "dense" if len(args[0]) <= 50 else "sparse"      # COLMAP's rule: DENSE_SCHUR up to 50 images
    tol = dict(ftol=FTOL, gtol=GTOL, xtol=XTOL, max_iter=MAX_ITER)

    def reference(package, method, **threads):
        def run():
            cams, pts, costs = package.bundle_adjust(*args, solver=method, **tol, **threads)
            return cams, pts, len(costs) - 1
        return run

    def ceres():
        cams, pts, _, summary = ch5.colmap_bundle_adjust(*args, stock_tolerances=True, max_iter=MAX_ITER,
                                                         colmap_gauge="TWO_CAMS_FROM_WORLD", return_summary=True)
        s = summary.ceres_summary
        ceres_solve.append((s.total_time_in_seconds, s.num_threads_used, str(s.linear_solver_type_used)))
        return cams, pts, s.num_successful_steps

    methods = {}
    if before_tree:
        methods["reference, before (its default: SuperLU)"] = reference(_package_from(before_tree, "ch05_before"), "auto")
    methods[f"reference ({solver} Schur)"] = reference(ba, solver)
    methods[f"reference ({solver} Schur, 2 threads)"] = reference(ba, solver, threads=2)
    methods["pycolmap / Ceres"] = ceres
    return methods


def _scipy_cookbook(args) -> tuple:
    """scipy.optimize.least_squares exactly as the SciPy cookbook ("Large-scale bundle adjustment in
    scipy"): trf, x_scale='jac', ftol=1e-4, 2-point Jacobian with its sparsity pattern. One run."""
    from scipy.optimize import least_squares
    from scipy.sparse import lil_matrix

    from solutions.ch05_bundle_adjustment import residuals

    cams, pts, ci, pi, obs = args
    nc, n_pts, m = len(cams), len(pts), len(ci)
    A = lil_matrix((2 * m, 9 * nc + 3 * n_pts), dtype=int)
    i = np.arange(m)
    for s in range(9):
        A[2 * i, ci * 9 + s] = A[2 * i + 1, ci * 9 + s] = 1
    for s in range(3):
        A[2 * i, 9 * nc + pi * 3 + s] = A[2 * i + 1, 9 * nc + pi * 3 + s] = 1

    def fun(x):
        return residuals(x[:9 * nc].reshape(nc, 9), x[9 * nc:].reshape(n_pts, 3), ci, pi, obs).ravel()

    wall, cpu = time.perf_counter(), time.process_time()
    res = least_squares(fun, np.r_[cams.ravel(), pts.ravel()], jac_sparsity=A, x_scale="jac", ftol=1e-4, method="trf")
    times = (time.perf_counter() - wall, time.process_time() - cpu)
    return res.x[:9 * nc].reshape(nc, 9), res.x[9 * nc:].reshape(n_pts, 3), res.njev - 1, times


def _measure(before_tree: str | None, repeat: int, with_scipy: bool, which: str) -> list[dict]:
    """All rows, in this process (the caller gives it one BLAS thread)."""
    from benchmarks.timing import taking_turns
    from graders import ch05_bundle_adjustment as ch5

    rows = []
    for name, args in _problems(which).items():
        nc, n_pts, m = len(args[0]), len(args[1]), len(args[4])
        print(f"\n{name}: {nc} cameras, {n_pts} points, {m} observations; initial cost {ch5.bal_cost(*args):.4e}; "
              f"load average {os.getloadavg()[0]:.1f}", flush=True)
        ceres_solve: list = []
        outputs, times = taking_turns(_methods(args, before_tree, ceres_solve), repeat=repeat if nc <= 50 else 1)
        if with_scipy and nc <= 50:
            cams, pts, steps, t = _scipy_cookbook(args)
            outputs["scipy least_squares (cookbook, ftol 1e-4, one run)"] = (cams, pts, steps)
            times["scipy least_squares (cookbook, ftol 1e-4, one run)"] = t
        ceres_name = "pycolmap / Ceres"
        solve = float(np.median([t for t, _, _ in ceres_solve]))
        ceres_cost = ch5.bal_cost(*outputs[ceres_name][:2], *args[2:])
        for method, (cams, pts, steps) in outputs.items():
            cost = ch5.bal_cost(cams, pts, *args[2:])
            wall, cpu = times[method]
            rows.append({"problem": name.split(" (")[0], "solver": method, "final cost": f"{cost:.5e}",
                         "cost / Ceres": f"{cost / ceres_cost:.4f}", "accepted steps": str(steps),
                         "wall s": f"{wall:.2f}", "CPU s": f"{cpu:.2f}",
                         "wall / Ceres solve": f"{wall / solve:.2f}x", "CPU / Ceres CPU": f"{cpu / times[ceres_name][1]:.2f}x",
                         "_cost": cost / ceres_cost, "_wall": wall / solve, "_cpu": cpu / times[ceres_name][1]})
        print(table([r for r in rows if r["problem"] == name.split(" (")[0]], COLUMNS), flush=True)
        threads, kind = ceres_solve[0][1], ceres_solve[0][2]
        print(f"Ceres: {kind}, {threads} threads; its own solve time (summary.total_time_in_seconds, median) {solve:.2f} s; "
              f"load average after {os.getloadavg()[0]:.1f}", flush=True)
    return rows


def _child(before_tree, repeat, with_scipy, which, queue) -> None:
    queue.put(_measure(before_tree, repeat, with_scipy, which))


def run(before_tree: str | None = None, repeat: int = 3, with_scipy: bool = True, which: str = "bal,street") -> list[dict]:
    """Measure in a child process whose BLAS runs one thread (set before numpy loads); print the table."""
    import multiprocessing

    keys = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    saved = {k: os.environ.get(k) for k in keys}
    os.environ.update({k: "1" for k in keys})
    try:
        ctx = multiprocessing.get_context("spawn")
        queue = ctx.Queue()
        proc = ctx.Process(target=_child, args=(before_tree, repeat, with_scipy, which, queue))
        proc.start()
        rows = queue.get()
        proc.join()
    finally:
        for k, v in saved.items():
            os.environ.pop(k) if v is None else os.environ.__setitem__(k, v)
    print()
    print(table(rows, COLUMNS))
    print("accepted steps: iterations that lowered the cost (reference: len(costs) - 1; Ceres: successful steps; scipy: "
          "Jacobian evaluations - 1). Ceres' wall and CPU times include building the COLMAP reconstruction and reading "
          "it back; 'wall / Ceres solve' divides by Ceres' own solve time alone.")
    for r in rows:
        if r["solver"].startswith("reference ("):
            met = r["_cost"] <= GOALS["cost vs Ceres"] and r["_wall"] <= GOALS["time vs Ceres"]
            print(f"  goal ({r['problem']}): cost <= Ceres' and wall time <= Ceres' solve time: "
                  f"{'met' if met else 'NOT MET'} (cost {r['_cost']:.4f}x, wall {r['_wall']:.2f}x, CPU {r['_cpu']:.2f}x)")
    return rows


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--before", help="a checkout whose solutions/ch05_bundle_adjustment to time as well")
    parser.add_argument("--repeat", type=int, default=3, help="timing rounds after the warm-up (BAL-49; street-300: 1)")
    parser.add_argument("--no-scipy", action="store_true", help="skip the SciPy cookbook run (~15-40 s)")
    parser.add_argument("--problems", default="bal,street", help="which problems: bal, street or both")
    a = parser.parse_args()
    run(a.before, a.repeat, not a.no_scipy, a.problems)
