"""Chapter 10: large-scale retrieval and Sim(3) merging against brute force and pycolmap, side by side.

- retrieval: the from-scratch vocabulary tree (`solutions.ch10_large_scale.retrieval`: build_index once,
  query_scores per query) vs brute-force descriptor matching of every query against every database image, on
  textured-plane renders of known places, at database sizes 9-240: mAP, recall@5, CPU time per query and in
  all (training included), and where the tree starts to win. Writes graders/ch10_large_scale/
  retrieval_scaling.json, which the chapter's notebook plots.
- sim3: the from-scratch Sim(3) RANSAC (10.7), before and after issues 30/32 (one hypothesis per Python turn,
  1000 always / batches of 64 with the adaptive count), vs pycolmap.estimate_sim3d_robust on the same pairs:
  scale / rotation error against the truth, held-out residual, and CPU time, the methods taking turns.
- merge: the from-scratch merge vs the grader's, and the similarity alone by Umeyama vs pycolmap, on the same
  shared points: errors against the truth and time.
- distributed: the Dask pipeline's wall time with 1 and 2 workers against the serial run (same rows).
- alignment: DUSt3R-style global alignment, the torch reference against the grader's scipy least squares.
"""
from __future__ import annotations

import numpy as np

from benchmarks.timing import table, taking_turns


SCALING_JSON = "graders/ch10_large_scale/retrieval_scaling.json"     # the notebook's figure reads it
PLACE_COUNTS = (3, 5, 10, 20, 40, 80)                                  # 9 to 240 database images


def _retrieval_row(n_places: int) -> dict:
    """One database size: the tree's index built once (its offline cost), then every query by the tree and by
    brute force, the two taking turns query by query; mAP and recall@5 from the same scores."""
    import time

    from graders import ch10_large_scale as ch10
    from solutions.ch10_large_scale.retrieval import build_index, query_scores

    P = ch10.place_problem(np.random.default_rng(n_places), n_places=n_places)
    db, qs, dl, ql = P["db_descriptors"], P["query_descriptors"], P["db_labels"], P["query_labels"]
    t0 = time.process_time()
    index = build_index(db)
    build = time.process_time() - t0
    S, S_bf, t_tree, t_bf = [], [], [], []
    for D in qs:
        t0 = time.process_time()
        S.append(query_scores(index, D))
        t1 = time.process_time()
        S_bf.append(ch10.brute_force_scores(db, [D])[0])
        t_bf.append(time.process_time() - t1)
        t_tree.append(t1 - t0)
    S, S_bf = np.array(S), np.array(S_bf)
    big = build_index(db, branching=10)                  # 10³ words: does a larger vocabulary close the mAP gap?
    S_big = np.array([query_scores(big, D) for D in qs])
    top = lambda M: np.argsort(-M, axis=1, kind="stable")[:, :5]  # noqa: E731
    return {"N": len(db), "Q": len(qs), "words": index["n_words"],
            "descriptors per image": float(np.mean([len(d) for d in db])),
            "mAP tree": ch10.mean_ap(S, dl, ql), "mAP brute": ch10.mean_ap(S_bf, dl, ql),
            "words k=10": big["n_words"], "mAP tree k=10": ch10.mean_ap(S_big, dl, ql),
            "touched": float(np.mean(S > 0)), "R@5 tree": ch10.recall_at_k(top(S), dl, ql),
            "R@5 brute": ch10.recall_at_k(top(S_bf), dl, ql),
            "build s": build, "query ms tree": 1e3 * float(np.median(t_tree)),
            "query ms brute": 1e3 * float(np.median(t_bf)),
            "all s tree": build + float(np.sum(t_tree)), "all s brute": float(np.sum(t_bf))}


def _one_blas_thread(fn, args) -> list:
    """[fn(a) for a in args] in a fresh process whose BLAS runs on one thread, as both methods would in a pipeline
    that gives each worker one core. On a busy 2-core machine a multi-threaded OpenBLAS spins: one 92 x 128 by
    128 x 92 product (brute force's inner step) cost 12.5 ms of CPU instead of 0.09 ms at a load of ~16, and that,
    not the matching, was most of brute force's time in issue 30's measurement. BLAS reads its thread count once,
    at import, hence the new process."""
    import multiprocessing
    import os

    keys = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
    before = {k: os.environ.get(k) for k in keys}
    os.environ.update({k: "1" for k in keys})
    try:
        with multiprocessing.get_context("spawn").Pool(1) as pool:
            return pool.map(fn, args)
    finally:
        for k, v in before.items():
            if v is None:
                os.environ.pop(k)
            else:
                os.environ[k] = v


def retrieval(write: bool = True) -> list[dict]:
    """The vocabulary tree (10.6's reference, k = 6, L = 3) against brute-force matching as the database grows:
    mAP, recall@5, CPU time per query (the tree's: descend its descriptors + walk the inverted-file lists of its
    words; brute force's: ratio-test matching against every database image) and in all (the tree's training
    and indexing counted once). Database: textured-plane renders of known places (ch10.place_problem: 3 photos
    of each place in the database, 1 query each, SIFT). Writes SCALING_JSON for the notebook's figure."""
    import json
    import os
    import time

    load = os.getloadavg()
    data = _one_blas_thread(_retrieval_row, PLACE_COUNTS)
    rows = [{"N db": d["N"], "words": d["words"], "mAP tree / brute": f"{d['mAP tree']:.3f} / {d['mAP brute']:.3f}",
             "mAP tree k=10 (words)": f"{d['mAP tree k=10']:.3f} ({d['words k=10']})",
             "R@5 tree / brute": f"{d['R@5 tree']:.2f} / {d['R@5 brute']:.2f}",
             "ms / query tree": f"{d['query ms tree']:.1f}", "ms / query brute": f"{d['query ms brute']:.1f}",
             "query brute / tree": f"{d['query ms brute'] / d['query ms tree']:.1f}x",
             "db images a tree query touches": f"{d['touched']:.0%}",
             "tree build s": f"{d['build s']:.2f}",
             "all queries s tree (incl. build) / brute": f"{d['all s tree']:.2f} / {d['all s brute']:.2f}"}
            for d in data]
    after = os.getloadavg()
    print(f"Retrieval on textured-plane renders of known places (3 database photos + 1 query each, SIFT), CPU time, "
          f"BLAS on one thread "
          f"(load average {load[0]:.1f} / {load[1]:.1f} on {os.cpu_count()} cores, after: {after[0]:.1f}):")
    print(table(rows, list(rows[0])))
    print("A brute-force query matches against all N images (linear in N, quadratic over N/3 queries); a tree query "
          "descends its descriptors (k L distances each) and walks the inverted-file lists of its words.")
    if write:
        path = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), SCALING_JSON)
        with open(path, "w") as f:
            json.dump({"written by": "python -m benchmarks 10 (benchmarks/ch10_large_scale.py: retrieval)",
                       "date": time.strftime("%Y-%m-%d"), "load average": [round(x, 1) for x in (*load, *after[:1])],
                       "cores": os.cpu_count(), "database": "ch10.place_problem renders, 3 db photos + 1 query a place, "
                       "OpenCV SIFT", "tree": "solutions.ch10_large_scale build_index / query_scores, k = 6, L = 3",
                       "rows": [{k: float(f"{v:.4g}") if isinstance(v, float) else v for k, v in d.items()}
                                for d in data]}, f, indent=1)
    return rows


def sim3_ransac_before(X: np.ndarray, Y: np.ndarray, threshold: float, iters: int = 1000,
                       seed: int = 0) -> tuple[float, np.ndarray, np.ndarray]:
    """10.7's reference before issues 30/32, kept as the "before" row: one hypothesis per Python-level turn,
    always `iters` of them; the same scoring (inlier count, ties by SSR) and the same two refits."""
    from solutions.geometry import umeyama

    X, Y = np.asarray(X, float), np.asarray(Y, float)
    rng = np.random.default_rng(seed)
    best, best_key = None, (-1, 0.0)
    for _ in range(iters):
        idx = rng.choice(len(X), 3, replace=False)
        if np.linalg.norm(np.cross(X[idx[1]] - X[idx[0]], X[idx[2]] - X[idx[0]])) < 1e-9:
            continue
        s, R, t = umeyama(X[idx], Y[idx])
        r2 = np.sum((s * X @ R.T + t - Y) ** 2, 1)
        inl = r2 < threshold ** 2
        key = (int(inl.sum()), -float(r2[inl].sum()))
        if key > best_key:
            best, best_key = inl, key
    inl = best
    for _ in range(2):
        s, R, t = umeyama(X[inl], Y[inl])
        inl = np.sum((s * X @ R.T + t - Y) ** 2, 1) < threshold ** 2
    return umeyama(X[inl], Y[inl])


SIM3_GOAL = 5.0          # issues 30/32: the reference within 5x pycolmap's time at the same accuracy


def _sim3_methods(P: dict, seed: int) -> dict:
    """name -> a call returning (s, R, t) on problem P: the reference before and after, and pycolmap's own
    model (its default RANSACOptions: confidence 0.9999, at least 1,000 trials; max_error = the threshold)."""
    import pycolmap

    from solutions.ch10_large_scale import sim3_ransac

    def colmap():
        opts = pycolmap.RANSACOptions()
        opts.max_error, opts.random_seed = float(P["threshold"]), seed
        out = pycolmap.estimate_sim3d_robust(P["X"], P["Y"], opts)["tgt_from_src"]
        return float(out.scale), np.asarray(out.rotation.matrix()), np.asarray(out.translation)
    args = (P["X"], P["Y"], P["threshold"])
    return {"reference before (1 hypothesis a turn, 1000)": lambda: sim3_ransac_before(*args),
            "reference (batches of 64, adaptive count)": lambda: sim3_ransac(*args),
            "pycolmap estimate_sim3d_robust": colmap}


def sim3(draws: int = 5, repeat: int = 3) -> list[dict]:
    """10.7: the reference Sim(3) RANSAC before and after against pycolmap, on the grader's three kinds of
    problem: scale / rotation error against the truth, held-out RMS / the truth's, and time (the three methods
    take turns in each of `repeat` timing rounds per draw; medians over `draws` draws)."""
    import os

    from graders import ch10_large_scale as ch10
    from graders.core.compare import rotation_angle_deg

    load = os.getloadavg()
    rows = []
    for outliers, planar in ((0.3, False), (0.5, False), (0.25, True)):
        per: dict = {}
        for seed in range(draws):
            P = ch10.sim3_problem(np.random.default_rng(seed), outliers=outliers, planar=planar)
            outs, times = taking_turns(_sim3_methods(P, seed), repeat)
            truth = ch10.held_rms((P["s"], P["R"], P["t"]), P)
            for name, S in outs.items():
                per.setdefault(name, []).append((abs(S[0] / P["s"] - 1), rotation_angle_deg(S[1], P["R"]),
                                                 ch10.held_rms(S, P) / truth, *times[name]))
        med = {name: np.median(np.array(v), axis=0) for name, v in per.items()}
        lib = med["pycolmap estimate_sim3d_robust"]
        for name, (es, eR, held, wall, cpu) in med.items():
            row = {"problem": f"{int(100 * outliers)} % outliers{' planar' if planar else ''}", "method": name,
                   "scale err": f"{es:.1e}", "rot deg": f"{eR:.3f}", "held-out RMS / truth": f"{held:.4f}",
                   "wall ms": f"{1e3 * wall:.1f}", "CPU ms": f"{1e3 * cpu:.1f}", "CPU / pycolmap": f"{cpu / lib[4]:.2f}x"}
            if name.startswith("reference ("):
                row["verdict"] = ("time OK" if cpu / lib[4] <= SIM3_GOAL else f"OVER {SIM3_GOAL:g}x") + \
                    (", held-out as good" if held <= 1.01 * lib[2] else ", HELD-OUT WORSE")
            rows.append(row)
    print(f"\nSim(3) RANSAC on 200 3D-3D pairs (medians of {draws} draws; in each, the methods take turns in "
          f"{repeat} timing rounds; load average {load[0]:.1f} / {load[1]:.1f} on {os.cpu_count()} cores, "
          f"after: {os.getloadavg()[0]:.1f}):")
    print(table(rows, list(rows[0]) + ["verdict"]))
    return rows


def merge() -> list[dict]:
    """Merging two sub-reconstructions: the reference merge vs the grader's, and the similarity alone by
    Umeyama vs pycolmap.estimate_sim3d_robust."""
    import time

    import pycolmap

    from graders import ch10_large_scale as ch10
    from graders.core.compare import rotation_angle_deg
    from solutions.ch10_large_scale import merge_reconstructions

    mrows = []
    for n_shared in (40, 8):
        P = ch10.merge_problem(np.random.default_rng(n_shared), n_shared=n_shared)
        res = {}
        for name, fn in (("reference", merge_reconstructions), ("grader (Umeyama + scipy BA)", ch10.gt_merge_reconstructions)):
            t0 = time.perf_counter()
            sim, merged = fn(P["rec_a"], P["rec_b"])
            dt = time.perf_counter() - t0
            cams = {i: (c["R"], c["t"]) for i, c in merged["cameras"].items()}
            res[name] = (ch10.gauge_errors(cams, merged["points"], P["truth"]), dt)
        shared = sorted(set(P["rec_a"]["points"]) & set(P["rec_b"]["points"]))
        Xb = np.array([P["rec_b"]["points"][p] for p in shared])
        Xa = np.array([P["rec_a"]["points"][p] for p in shared])
        opts = pycolmap.RANSACOptions()
        opts.max_error = 0.5 * float(np.median(np.linalg.norm(Xa - Xa.mean(0), axis=1)))
        sc = pycolmap.estimate_sim3d_robust(Xb, Xa, opts)["tgt_from_src"]
        from graders.kit.geometry import umeyama
        su = umeyama(Xb, Xa)
        for name, (e, dt) in res.items():
            mrows.append({"shared": n_shared, "merge": name, "centres mm": f"{1e3 * e[0]:.1f}", "points mm": f"{1e3 * e[1]:.1f}",
                          "similarity rotation": "", "time s": f"{dt:.2f}"})
        mrows.append({"shared": n_shared, "merge": "similarity only: Umeyama / pycolmap",
                      "centres mm": "", "points mm": "",
                      "similarity rotation": f"{rotation_angle_deg(su[1], P['sim_ba'][1]):.2f} / "
                           f"{rotation_angle_deg(np.asarray(sc.rotation.matrix()), P['sim_ba'][1]):.2f} deg", "time s": ""})
    print("\nMerging two sub-reconstructions (10 cm errors each), errors after the gauge alignment to the truth:")
    print(table(mrows, list(mrows[0])))
    return mrows


def distributed() -> list[dict]:
    """The Dask pipeline (10.10's reference: workers load the images from paths, batches of 3) with 1 and 2 workers
    against the serial run, same stages (each stage call sleeps 0-12 ms: the I/O a real extraction or matching task
    waits on), and the rows compared."""
    import os
    import tempfile
    import time

    from graders import ch10_large_scale as ch10
    from solutions.ch10_large_scale import run_pipeline
    from solutions.ch10_large_scale.distributed import unique_pairs

    rows = []
    images, pairs = ch10.pipeline_images(np.random.default_rng(0), n_images=7)
    stages = ch10.PipelineStages()
    t0 = time.perf_counter()
    feats = [stages.extract(im) for im in images]
    serial = np.array([(i, j, stages.verify(feats[i], feats[j], stages.match(feats[i], feats[j])))
                       for i, j in unique_pairs(pairs)], int)
    t_serial = time.perf_counter() - t0
    rows.append({"run": "serial", "tasks": len(images) + 2 * len(serial), "seconds": f"{t_serial:.2f}",
                 "vs serial": "1.00x", "same rows": "-"})
    batch = 3
    tasks = -(-len(images) // batch) + -(-len(serial) // batch)       # batches of images + batches of pairs
    for workers in (1, 2):
        with tempfile.TemporaryDirectory() as folder:
            paths = ch10.save_images(images, folder)
            t0 = time.perf_counter()
            out = run_pipeline(paths, pairs, stages, os.path.join(folder, "m.json"), n_workers=workers,
                               batch_size=batch)
            dt = time.perf_counter() - t0
        rows.append({"run": f"Dask LocalCluster, {workers} worker{'s' * (workers > 1)} (incl. start/stop)",
                     "tasks": tasks, "seconds": f"{dt:.2f}",
                     "vs serial": f"{t_serial / dt:.2f}x", "same rows": str(np.array_equal(out, serial))})
    print("\nMap/reduce matching pipeline (7 images, batches of 3, every stage call 0-12 ms of simulated I/O):")
    print(table(rows, list(rows[0])))
    return rows


def alignment() -> list[dict]:
    """10.9: the reference (spanning tree + Adam, torch) against the grader's scipy least squares: pose errors
    after the gauge and time, on simulated pointmaps."""
    import time

    from graders import ch10_large_scale as ch10
    from solutions.ch10_large_scale import global_alignment

    rows = []
    for n_views in (6, 10):
        d = ch10.pointmap_scene(np.random.default_rng(n_views), n_views=n_views)
        res = {}
        for name, fn in (("reference (Adam)", global_alignment), ("scipy least squares", ch10.gt_global_alignment)):
            t0 = time.process_time()
            Rs, ts, sigma = fn(d["pairs"], n_views)
            res[name] = (ch10.alignment_errors({"Rs": Rs, "ts": ts, "sigma": sigma}, d), time.process_time() - t0)
        for name, (e, dt) in res.items():
            rows.append({"views": n_views, "solver": name, "rot RMS deg": f"{np.sqrt(np.mean(e['rot_deg'] ** 2)):.3f}",
                         "worst centre": f"{e['centre'].max():.2%}", "CPU s": f"{dt:.2f}",
                         "time vs scipy": f"{dt / res['scipy least squares'][1]:.2f}x"})
    print("\nGlobal alignment of pairwise pointmaps (errors after the Sim(3) gauge):")
    print(table(rows, list(rows[0])))
    return rows


SECTIONS = [retrieval, sim3, merge, distributed, alignment]


def run() -> list[dict]:
    rows: list[dict] = []
    for section in SECTIONS:
        rows += section()
    return rows


if __name__ == "__main__":
    run()
