"""Chapter 8: stereo on the real Middlebury motorcycle pair, the reference block matcher and SGM
beside OpenCV's StereoBM and StereoSGBM (stereo_table), and neural's NeRF / 3DGS figures
(neural_table, appended by neural)."""
from __future__ import annotations


def stereo_table() -> str:
    return "stereo_table: not built yet"


def run() -> None:
    print(stereo_table())
    table = globals().get("neural_table")
    if table is not None:
        print(table())
