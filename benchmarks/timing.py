"""Shared timing and table helpers for benchmarks."""
from __future__ import annotations

import statistics
import time
from typing import Callable


def median_time(fn: Callable[[], object], repeat: int = 7) -> float:
    """Median wall time of `fn()` in seconds over `repeat` runs (after one warm-up run)."""
    fn()
    times = []
    for _ in range(repeat):
        start = time.perf_counter()
        fn()
        times.append(time.perf_counter() - start)
    return sorted(times)[len(times) // 2]


def table(rows: list[dict], columns: list[str]) -> str:
    """A plain text table of `rows` (dicts) with the given column order."""
    cells = [[str(r.get(c, "")) for c in columns] for r in rows]
    widths = [max(len(c), *(len(row[i]) for row in cells)) for i, c in enumerate(columns)]
    line = "  ".join(c.ljust(w) for c, w in zip(columns, widths))
    body = ["  ".join(v.ljust(w) for v, w in zip(row, widths)) for row in cells]
    return "\n".join([line, "  ".join("-" * w for w in widths), *body])


def taking_turns(methods: dict[str, Callable[[], object]], repeat: int = 5) -> tuple[dict, dict]:
    """Run every `fn()` of `methods` once (a warm-up, whose result is returned), then `repeat` rounds in
    which the methods take turns, so that a load spike on a shared machine falls on all of them alike
    rather than on whichever was being timed.

    Returns (outputs: name -> the warm-up call's result, times: name -> (median wall s, median process CPU s))."""
    outputs = {name: fn() for name, fn in methods.items()}
    wall: dict[str, list[float]] = {name: [] for name in methods}
    cpu: dict[str, list[float]] = {name: [] for name in methods}
    for _ in range(repeat):
        for name, fn in methods.items():
            w, c = time.perf_counter(), time.process_time()
            fn()
            wall[name].append(time.perf_counter() - w)
            cpu[name].append(time.process_time() - c)
    return outputs, {name: (statistics.median(wall[name]), statistics.median(cpu[name])) for name in methods}
