"""Chapter 5's library bundle adjusters: Ceres through pycolmap, scipy (graders.oracles.bundle_adjust),
and the stand-in for 5.14 built on them."""
from __future__ import annotations

import numpy as np

from graders.oracles.bundle_adjust import bal_cost, scipy_bundle_adjust

from .problems import F


def library_bundle_adjust(cameras, points, cam_idx, pt_idx, obs, loss: str = "linear", scale: float = 1.0,
                          fix_gauge: bool = False, max_iter: int = 50):
    """Stand-in for `bundle_adjust`: Ceres through pycolmap (fast, any loss; observations behind a
    camera are left out), and scipy's least_squares when `fix_gauge` asks for this chapter's exact
    gauge convention. `costs` has one entry per iteration either way (Ceres run one iteration at a time)."""
    if fix_gauge:
        return scipy_bundle_adjust(cameras, points, cam_idx, pt_idx, obs, loss, scale, fix_gauge, max_iter)
    return colmap_bundle_adjust(cameras, points, cam_idx, pt_idx, obs, loss, scale, max_iter=max_iter,
                                per_iteration=True)


def bal_to_reconstruction(cameras, points, cam_idx, pt_idx, obs, keep: np.ndarray | None = None):
    """A pycolmap Reconstruction of a BAL problem: one RADIAL camera (f, cx = cy = 0, k1, k2), rig
    and frame per BAL camera; poses and pixels flipped into COLMAP's (= OpenCV's) axes by F.
    keep: which observations to include (default all). Returns (reconstruction, point ids (np,))."""
    from scipy.spatial.transform import Rotation
    import pycolmap

    cameras, points, obs = np.asarray(cameras, float), np.asarray(points, float), np.asarray(obs, float)
    keep = np.ones(len(obs), bool) if keep is None else np.asarray(keep, bool)
    rec = pycolmap.Reconstruction()
    kp_index = np.full(len(obs), -1)
    for i, c in enumerate(cameras):
        cam = pycolmap.Camera.create_from_model_name(i + 1, "RADIAL", float(c[6]), 2000, 2000)
        cam.params = [c[6], 0.0, 0.0, c[7], c[8]]
        rec.add_camera_with_trivial_rig(cam)
        sel = np.flatnonzero((cam_idx == i) & keep)
        kp_index[sel] = np.arange(len(sel))
        image = pycolmap.Image(name=f"{i}", keypoints=np.c_[obs[sel, 0], -obs[sel, 1]], camera_id=i + 1,
                               image_id=i + 1)
        R = F @ Rotation.from_rotvec(c[:3]).as_matrix()
        rec.add_image_with_trivial_frame(image, pycolmap.Rigid3d(pycolmap.Rotation3d(R), F @ c[3:6]))
    ids = np.full(len(points), -1, np.int64)  # -1: a point COLMAP cannot take (fewer than 2 observations)
    order = np.argsort(pt_idx, kind="stable")
    bounds = np.searchsorted(pt_idx[order], np.arange(len(points) + 1))
    for j in range(len(points)):
        mine = [o for o in order[bounds[j]:bounds[j + 1]] if keep[o]]
        if len(mine) < 2:
            continue
        track = pycolmap.Track()
        for o in mine:
            track.add_element(int(cam_idx[o]) + 1, int(kp_index[o]))
        ids[j] = rec.add_point3D(points[j], track)
    return rec, ids


def reconstruction_to_bal(rec, ids, n_cams: int, points: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Cameras (nc, 9) and points (np, 3) back from a Reconstruction made by bal_to_reconstruction
    (points it left out keep their values from `points`)."""
    from scipy.spatial.transform import Rotation
    cams = np.zeros((n_cams, 9))
    for i in range(n_cams):
        pose = rec.image(i + 1).cam_from_world()
        R = F @ pose.rotation.matrix()
        p = rec.camera(i + 1).params
        cams[i] = np.r_[Rotation.from_matrix(R).as_rotvec(), F @ pose.translation, p[0], p[3], p[4]]
    out = np.zeros((len(ids), 3)) if points is None else np.array(points, float)
    for k, j in enumerate(ids):
        if j >= 0:
            out[k] = rec.point3D(int(j)).xyz
    return cams, out


def colmap_bundle_adjust(cameras, points, cam_idx, pt_idx, obs, loss: str = "linear", scale: float = 1.0,
                         fix_gauge: bool = False, max_iter: int = 50, stock_tolerances: bool = True,
                         tight: bool = False, colmap_gauge: str | None = None, return_summary: bool = False,
                         per_iteration: bool = False):
    """pycolmap-backed `bundle_adjust` (Ceres, Schur-based LM). Observations whose point is behind
    the camera are left out (COLMAP zeroes their residuals), and so are points left with fewer
    than two observations (COLMAP refuses them; they are returned unchanged). With stock_tolerances, Ceres' own
    defaults (function 1e-6, gradient 1e-10, parameter 1e-8) replace COLMAP's (0, 1e-4, 0); `tight`
    uses 1e-12 everywhere and up to 200 iterations (an oracle for the converged cost).
    fix_gauge holds camera 0's pose (COLMAP fixes scale its own way: the cost is the same).
    colmap_gauge: a `pycolmap.BundleAdjustmentGauge` name; 'TWO_CAMS_FROM_WORLD' makes this exactly
    what `pycolmap.bundle_adjustment(reconstruction, options)` runs.
    per_iteration: run Ceres one iteration per solve, carrying LM's trust-region radius from call to
    call as Ceres does inside one solve (radius x3 after a successful step, / nu after a failed one,
    nu doubling), so that costs records the BAL cost after every iteration (up to max_iter). A step is
    accepted only if the BAL cost over all observations drops too; it stops once an accepted step
    lowers the cost by less than 1e-12 relative, the radius collapses, or three Ceres steps in a row
    lower COLMAP's cost but not the BAL cost (observations behind a camera: the two costs disagree).
    Returns (cameras, points, costs = [initial, final], or one entry per iteration with per_iteration)
    (+ the Ceres summary of the last solve if return_summary)."""
    from scipy.spatial.transform import Rotation
    import pycolmap

    cameras, points = np.asarray(cameras, float), np.asarray(points, float)
    cam_idx, pt_idx, obs = np.asarray(cam_idx), np.asarray(pt_idx), np.asarray(obs, float)
    c = cameras[cam_idx]
    depth = (Rotation.from_rotvec(c[:, :3]).apply(points[pt_idx]) + c[:, 3:6])[:, 2]
    rec, ids = bal_to_reconstruction(cameras, points, cam_idx, pt_idx, obs, keep=depth < 0)
    options = _colmap_options(pycolmap, loss, scale, max_iter, tight, stock_tolerances)
    config = pycolmap.BundleAdjustmentConfig()
    for i in range(len(cameras)):
        config.add_image(i + 1)
    if fix_gauge:
        config.set_constant_rig_from_world_pose(rec.image(1).frame_id)
    if colmap_gauge is not None:
        config.fix_gauge(getattr(pycolmap.BundleAdjustmentGauge, colmap_gauge))
    level = pycolmap.logging.minloglevel
    pycolmap.logging.minloglevel = 2  # Ceres' warnings about retried steps would land in the notebook
    costs = [bal_cost(cameras, points, cam_idx, pt_idx, obs, loss, scale)]
    try:
        if not per_iteration:
            summary = pycolmap.create_default_bundle_adjuster(options, config, rec).solve()
        else:
            rec, ids, summary, costs = _solve_per_iteration(pycolmap, options, config, rec, ids, (
                cameras, points, cam_idx, pt_idx, obs), depth < 0, loss, scale, max_iter, costs)
    finally:
        pycolmap.logging.minloglevel = level
    new_cams, new_pts = reconstruction_to_bal(rec, ids, len(cameras), points)
    if per_iteration:
        costs[-1] = bal_cost(new_cams, new_pts, cam_idx, pt_idx, obs, loss, scale)
    else:
        costs.append(bal_cost(new_cams, new_pts, cam_idx, pt_idx, obs, loss, scale))
    return (new_cams, new_pts, costs, summary) if return_summary else (new_cams, new_pts, costs)


def _colmap_options(pycolmap, loss: str, scale: float, max_iter: int, tight: bool, stock_tolerances: bool):
    """COLMAP's bundle-adjustment options for `colmap_bundle_adjust` (loss, iterations, tolerances)."""
    options = pycolmap.BundleAdjustmentOptions()
    options.refine_principal_point = False
    options.print_summary = False
    ceres = options.ceres
    if loss != "linear":
        ceres.loss_function_type = {"huber": pycolmap.LossFunctionType.HUBER,
                                    "cauchy": pycolmap.LossFunctionType.CAUCHY}[loss]
        ceres.loss_function_scale = float(scale)
    so = ceres.solver_options
    so.max_num_iterations = max_iter
    if tight:
        so.function_tolerance = so.gradient_tolerance = so.parameter_tolerance = 1e-12
        so.max_num_iterations = max(max_iter, 200)
    elif stock_tolerances:
        so.function_tolerance, so.gradient_tolerance, so.parameter_tolerance = 1e-6, 1e-10, 1e-8
    return options


def _solve_per_iteration(pycolmap, options, config, rec, ids, problem: tuple, keep: np.ndarray, loss: str,
                         scale: float, max_iter: int, costs: list[float]):
    """Ceres one iteration per solve, LM's trust-region radius carried from call to call (see
    `colmap_bundle_adjust`). Returns (reconstruction, point ids, last Ceres summary, costs)."""
    cameras, points, cam_idx, pt_idx, obs = problem
    so = options.ceres.solver_options
    so.max_num_iterations = 1
    so.function_tolerance = so.gradient_tolerance = so.parameter_tolerance = 0.0
    radius, nu = so.initial_trust_region_radius, 2.0
    current, disagreements, summary = (cameras, points), 0, None
    for _ in range(max_iter):
        so.initial_trust_region_radius = radius
        summary = pycolmap.create_default_bundle_adjuster(options, config, rec).solve()
        cs = summary.ceres_summary
        ok = cs.num_successful_steps > 0 and cs.final_cost < cs.initial_cost
        if ok:  # accepted only if the BAL cost over *all* observations drops too (COLMAP's cost
            # zeroes observations whose point crosses behind the camera)
            trial = reconstruction_to_bal(rec, ids, len(cameras), points)
            new_cost = bal_cost(*trial, cam_idx, pt_idx, obs, loss, scale)
            ok = new_cost < costs[-1]
            if not ok:
                disagreements += 1
                rec, ids = bal_to_reconstruction(*current, cam_idx, pt_idx, obs, keep=keep)
            else:
                disagreements = 0
        decrease = (costs[-1] - new_cost) / max(costs[-1], 1e-300) if ok else 0.0
        radius, nu = (min(3 * radius, 1e16), 2.0) if ok else (radius / nu, 2 * nu)
        if ok:
            current = trial
        costs.append(new_cost if ok else costs[-1])
        # Three Ceres steps in a row that lower COLMAP's cost but not the BAL cost: the two costs
        # disagree (observations behind a camera), and Ceres has gone as far as it can.
        if (ok and decrease < 1e-12) or radius < 1e-32 or costs[-1] == 0 or disagreements >= 3:
            costs = costs[:len(costs) - disagreements] if disagreements >= 3 else costs
            break
    return rec, ids, summary, costs
