"""Chapter 9: from-scratch flow vs OpenCV on the FlyingChairs pair and synthetic pairs, side by side.

(Being built: the dense-flow and sparse-LK tables land with exercises 9.11 and 9.13.)
"""
from __future__ import annotations


def run() -> list[dict]:
    print("chapter 9 benchmark: not built yet")
    return []
