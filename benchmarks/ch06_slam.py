"""Chapter 6: pose-graph optimisation of the real intel (SE(2)) and parking-garage (SE(3)) graphs,
the reference optimiser and GTSAM side by side (pose_graph_table), and front-end's trajectory
metrics against evo (trajectory_table, appended by front-end)."""
from __future__ import annotations


def pose_graph_table() -> str:
    return "pose_graph_table: not built yet"


def run() -> None:
    print(pose_graph_table())
    table = globals().get("trajectory_table")
    if table is not None:
        print(table())


# ----------------------------------------------------------------- front-end (6.12): trajectory metrics vs evo

def trajectory_table() -> str:
    """ATE/RPE of the reference `trajectory_errors` and of evo 1.38.1 on the TUM freiburg1_xyz RGBD-SLAM
    estimate vs its ground truth, side by side: the figures (must agree to 1e-6 m) and the time per
    evaluation (association + alignment + metrics; evo's through its PoseTrajectory3D objects)."""
    from benchmarks.timing import median_time, table
    from graders import datasets
    from graders.ch06_slam import evo_trajectory_errors, load_tum_pair
    from solutions.ch06_slam import trajectory_errors

    if not datasets.available("trajectories"):
        return "trajectory_table: TUM trajectories not available (python -m graders.datasets fetch trajectories)"
    pair = load_tum_pair()
    rows = []
    for with_scale, delta in [(False, 1), (True, 1), (False, 30)]:
        ours = trajectory_errors(**pair, with_scale=with_scale, delta=delta)
        evo = evo_trajectory_errors(**pair, with_scale=with_scale, delta=delta)
        t_ours = median_time(lambda: trajectory_errors(**pair, with_scale=with_scale, delta=delta), repeat=5)
        t_evo = median_time(lambda: evo_trajectory_errors(**pair, with_scale=with_scale, delta=delta), repeat=5)
        rows.append({
            "alignment": "Sim(3)" if with_scale else "SE(3)", "delta": delta,
            "ATE ours (m)": f"{ours[0]:.6f}", "ATE evo (m)": f"{evo[0]:.6f}",
            "RPE_t ours (m)": f"{ours[1]:.6f}", "RPE_t evo (m)": f"{evo[1]:.6f}",
            "RPE_r ours (deg)": f"{ours[2]:.5f}", "RPE_r evo (deg)": f"{evo[2]:.5f}",
            "max |diff|": f"{abs(ours[:3] - evo[:3]).max():.1e}",
            "ours (ms)": f"{t_ours * 1e3:.1f}", "evo (ms)": f"{t_evo * 1e3:.1f}", "evo / ours": f"{t_evo / t_ours:.1f}x",
        })
    return "TUM freiburg1_xyz, RGBD-SLAM vs ground truth (evo 1.38.1 side by side)\n" + table(rows, list(rows[0]))
