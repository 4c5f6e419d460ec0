"""10.10's given pipeline stages (`PipelineStages`: load, extract, match, verify) and the failure injection the judge
arms them with: tasks that fail once (transient), a cluster that goes down after a number of verifications
(permanent), and the marker files through which the judge sees what ran, where, when, and which pairs a stage call
verified. The judging itself is in `distributed`."""
from __future__ import annotations

import os
import time
import zlib

import numpy as np


class TransientTaskError(RuntimeError):
    """A task that fails once and succeeds when retried (a pre-empted node, a network blip)."""


class PermanentTaskError(RuntimeError):
    """A task that fails however often it is retried (here: the cluster going down mid-run)."""


class PipelineStages:
    """The pipeline's four stages (not callable itself: its methods are the tasks).

    load(path) -> image (H, W) float, read from a `.npy` file (`save_images` writes them);
    extract(image (H, W)) -> (kp (K, 2) float, desc (K, 25) float); match(f1, f2) -> (M, 2) int indices;
    verify(f1, f2, matches) -> int, the inliers of the best translation (within 1.5 px).
    flaky: task keys (`task_key`: the stage's name and a checksum of its inputs) that fail the first time
    they run (marker files in `scratch` make "first" exact across threads and processes).
    paths: if given, the only paths `load` reads (the judge's own images: learner code never makes it read
    another file). crash_after: every verification after that many (counted in `scratch`) raises
    `PermanentTaskError`. A verification that does not fail leaves `.ok-<pair_key>` in `scratch` (which pairs were
    verified through these stages).
    Graded mode serves its methods concurrently (`served_concurrently`): two tasks the learner's Dask workers run
    at once are two stage calls in the judge at once, which `_after_run` sees in the markers' time windows.
    """
    served_concurrently = True
    # The failure injection (_flaky, _scratch, _crash_after) and `_reliable` are private: graded mode's proxy refuses
    # `_` names, so learner code can neither read which run is meant to crash nor fetch an unmarked copy whose calls
    # the resume row would not count (a found bypass: `stages.reliable()` then scored the resume row). In self-study
    # they are within reach; there the judge fails stages whose state the run changed, and the resume row wants each
    # pair the crash left unverified verified by these stages (their `.ok-` markers), which no copy's calls leave.

    def __init__(self, n_corners: int = 40, flaky: tuple[str, ...] = (), scratch: str | None = None,
                 latency_s: float = 0.012, paths: tuple[str, ...] = (), crash_after: int | None = None):
        self.n_corners, self._flaky, self._scratch, self.latency_s = n_corners, tuple(flaky), scratch, latency_s
        self.paths, self._crash_after = tuple(str(p) for p in paths), crash_after

    def _state(self) -> tuple:
        return self.n_corners, self._flaky, self._scratch, self.latency_s, self.paths, self._crash_after

    def __eq__(self, other) -> bool:      # by value: the sandbox compares a copy of the inputs after the call
        return isinstance(other, PipelineStages) and self._state() == other._state()

    def __hash__(self) -> int:
        return hash(self._state())

    def _reliable(self) -> "PipelineStages":
        return PipelineStages(self.n_corners, (), None, 0.0, self.paths)

    # -- failure injection and scrambled latencies
    def _task(self, kind: str, *inputs) -> None:
        key = task_key(kind, *inputs)
        start = time.monotonic_ns()
        if self.latency_s:
            time.sleep(self.latency_s * (zlib.crc32(key.encode()) % 97) / 96)
        if self._scratch is not None:
            _record_where(self._scratch, kind, start)
        if self._crash_after is not None and kind == "verify" and _runs(self._scratch, "verify") > self._crash_after:
            raise PermanentTaskError(f"task {key} failed: the cluster is down (simulated); the run cannot finish")
        if key not in self._flaky or self._scratch is None:
            return
        try:   # first call only: O_EXCL makes "first" exact across threads and processes
            os.close(os.open(os.path.join(self._scratch, f".failed-{key}"), os.O_CREAT | os.O_EXCL | os.O_WRONLY))
        except FileExistsError:   # a retry: the failed task ran again through these stages (`retried` counts it)
            try:
                os.close(os.open(os.path.join(self._scratch, f".retried-{key}"), os.O_CREAT | os.O_WRONLY))
            except OSError:
                pass
            return
        _lose_this_worker(self._scratch)
        raise TransientTaskError(f"task {key} failed transiently (simulated: its worker was lost); retry it")

    # -- the stages
    def load(self, path: str) -> np.ndarray:
        path = os.fspath(path)
        if self.paths and path not in self.paths:
            raise ValueError(f"{path!r} is not one of the pipeline's images")
        self._task("load", path)
        with _open_no_link(path, "rb") as f:            # never through a link planted in the folder
            image = np.load(f, allow_pickle=False)
        if image.ndim != 2 or image.dtype != np.float64:
            raise ValueError(f"{path!r} is not an (H, W) float image")
        return image

    def extract(self, image: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        self._task("extract", image)
        img = np.asarray(image, float)
        gy, gx = np.gradient(img)
        box = lambda a: sum(np.roll(np.roll(a, dy, 0), dx, 1) for dy in (-1, 0, 1) for dx in (-1, 0, 1))
        Sxx, Syy, Sxy = box(gx * gx), box(gy * gy), box(gx * gy)
        H = Sxx * Syy - Sxy ** 2 - 0.05 * (Sxx + Syy) ** 2           # Harris response
        H[:4], H[-4:], H[:, :4], H[:, -4:] = -np.inf, -np.inf, -np.inf, -np.inf
        peak = H == np.max([np.roll(np.roll(H, dy, 0), dx, 1) for dy in (-2, -1, 0, 1, 2) for dx in (-2, -1, 0, 1, 2)], 0)
        ys, xs = np.nonzero(peak & np.isfinite(H))
        order = np.lexsort((xs, ys, -H[ys, xs]))[:self.n_corners]  # strongest first, ties by position
        ys, xs = ys[order], xs[order]
        patches = np.array([img[y - 2:y + 3, x - 2:x + 3].ravel() for y, x in zip(ys, xs)]).reshape(-1, 25)
        patches = patches - patches.mean(1, keepdims=True)
        desc = patches / np.maximum(np.linalg.norm(patches, axis=1, keepdims=True), 1e-12)
        return np.c_[xs, ys].astype(float), desc

    def match(self, f1, f2) -> np.ndarray:
        self._task("match", f1[0], f2[0])
        d = 2 - 2 * f1[1] @ f2[1].T                                    # squared distance of unit descriptors
        if d.size == 0:
            return np.zeros((0, 2), int)
        a, b = np.argmin(d, 1), np.argmin(d, 0)
        i = np.flatnonzero(b[a] == np.arange(len(a)))                  # mutual nearest neighbours
        return np.c_[i, a[i]].astype(int)

    def verify(self, f1, f2, matches) -> int:
        self._task("verify", f1[0], f2[0])
        if self._scratch is not None:     # it did not fail: the pair this call verifies (the resume row's evidence)
            try:
                marker = os.path.join(self._scratch, f".ok-{pair_key(f1[0], f2[0])}")
                os.close(os.open(marker, os.O_CREAT | os.O_WRONLY))
            except OSError:
                pass
        m = np.asarray(matches, int).reshape(-1, 2)
        if len(m) == 0:
            return 0
        shift = f2[0][m[:, 1]] - f1[0][m[:, 0]]                        # each match's translation
        close = np.linalg.norm(shift[:, None] - shift[None], axis=2) <= 1.5
        return int(close.sum(1).max())                                 # every match tried as the hypothesis


def task_key(kind: str, *inputs) -> str:
    """A task's identity from its inputs (what a content-addressed cache would use)."""
    crc = 0
    for a in inputs:
        crc = zlib.crc32(a.encode() if isinstance(a, str) else np.ascontiguousarray(a, float).tobytes(), crc)
    return f"{kind}-{crc:08x}"


def pair_key(kp1, kp2) -> str:
    """A pair's identity whichever way round it is verified: the checksums of its two images' keypoints, sorted."""
    return "-".join(sorted(f"{zlib.crc32(np.ascontiguousarray(k, float).tobytes()):08x}" for k in (kp1, kp2)))


def _scheduler_of(worker) -> str | None:
    return getattr(getattr(worker, "scheduler", None), "address", None)


def _workers_here():
    """(this task's Dask worker or None, running workers of this process on its scheduler, running workers of
    this process on other schedulers — a cluster an earlier run left open)."""
    try:
        from distributed import Worker, get_worker
        from distributed.core import Status
        worker = get_worker()
        running = [w for w in list(Worker._instances) if w.status == Status.running]
    except Exception:        # not on a Dask worker (serial loop, threads scheduler)
        return None, [], []
    ours = [w for w in running if _scheduler_of(w) == _scheduler_of(worker)]
    return worker, ours, [w for w in running if _scheduler_of(w) != _scheduler_of(worker)]


def _record_where(scratch: str, kind: str, start_ns: int) -> None:
    """One marker file per task run: on a Dask worker or not, how many workers of other schedulers (a cluster
    left open by an earlier run) were running in the process, and the time window of its latency
    (time.monotonic_ns() at its start and now)."""
    worker, _, others = _workers_here()
    name = (f".ran-{kind}-{'worker' if worker is not None else 'local'}-{len(others)}-{os.getpid()}-{start_ns}-"
            f"{time.monotonic_ns()}")
    try:
        os.close(os.open(os.path.join(scratch, name), os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except OSError:
        pass


def retried(scratch: str, groups: list[tuple[str, ...]]) -> int:
    """How many of the flaky tasks (each a group of keys: a verification's two orders) were not both failed and run
    again through the stages: a run that never called them, or called an unmarked copy instead of retrying."""
    names = set(os.listdir(scratch))
    return sum(not any(f".failed-{k}" in names and f".retried-{k}" in names for k in keys) for keys in groups)


def _runs(scratch: str | None, kind: str) -> int:
    """How many runs of a stage the markers in `scratch` record."""
    return sum(n.startswith(f".ran-{kind}-") for n in os.listdir(scratch)) if scratch else 0


def _lose_this_worker(scratch: str) -> None:
    """If this task runs on a Dask worker and another worker of the same scheduler is still running, close
    this one (the scheduler then reruns its tasks elsewhere), once per run. The last worker of a scheduler is
    never closed: the run would wait forever for a worker, which is a test of patience, not of retries. Workers
    of another scheduler (a cluster an earlier run left open) do not count: with them counted, the run's own last
    worker was closed and the check hung until its time limit. Once per run: two flaky tasks running at the same
    time on the two workers each saw the other still running and both closed theirs (the close is asynchronous),
    and the run hung the same way (seen in the contract suite, 10.10's mutants graded one after another)."""
    worker, ours, _ = _workers_here()
    if worker is None or len(ours) < 2:
        return
    try:   # O_EXCL: exactly one task of the run closes its worker, across threads and processes
        os.close(os.open(os.path.join(scratch, ".lost-worker"), os.O_CREAT | os.O_EXCL | os.O_WRONLY))
    except FileExistsError:
        return
    worker.loop.add_callback(worker.close, timeout=2)


def _open_no_link(path: str, mode: str):
    """The judge never follows a link the learner's code may have put in its folder."""
    flags = (os.O_WRONLY | os.O_CREAT | os.O_TRUNC if "w" in mode else os.O_RDONLY) | os.O_NOFOLLOW
    return os.fdopen(os.open(path, flags, 0o644), mode)
