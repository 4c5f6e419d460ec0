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
