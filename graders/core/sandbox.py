"""Call untrusted learner code and describe what happened, whatever it does.

`safe_call` never raises for anything the callee does (exceptions, `sys.exit`, endless loops,
floods of output, mutating its arguments); it returns an `Outcome` that says what went wrong.
Only `KeyboardInterrupt` is let through, so a learner can still stop a cell.

Time limits count the CPU time of the learner's thread, with a wall-clock backstop for code that
waits; a watcher thread raises the limit in the main thread with SIGALRM, which interrupts Python
code (an endless `while` loop) but not a single long C call, and works only in the main thread (a
notebook cell and `python -m graders` both run there). The shell grader adds a hard per-exercise
limit by running every notebook in a worker process it can kill (see `graders.grading.runner`).
"""
from __future__ import annotations

import contextlib
import contextvars
import copy
import io
import signal
import threading
import time
import traceback
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

OUTPUT_CAP = 2_000  # characters of learner print output kept per call


class TimeLimitExceeded(BaseException):
    """Raised inside learner code when its time is up (BaseException: a bare `except Exception` in
    learner code cannot swallow it)."""


@dataclass
class Outcome:
    value: Any = None
    error: str | None = None          # one-line description of what went wrong, None if it returned
    kind: str = "ok"                  # ok | not_implemented | exception | timeout | exit
    traceback: str = ""
    stdout: str = ""                  # captured output, capped at OUTPUT_CAP characters
    stdout_truncated: int = 0         # characters dropped
    mutated: list[str] = field(default_factory=list)  # names of arguments the callee changed
    seconds: float = 0.0


class _CappedWriter(io.TextIOBase):
    """A text stream that keeps the first `cap` characters and counts the rest."""

    def __init__(self, cap: int):
        self.cap, self.parts, self.kept, self.dropped = cap, [], 0, 0

    def write(self, s: str) -> int:
        room = self.cap - self.kept
        if room > 0:
            self.parts.append(s[:room])
            self.kept += min(room, len(s))
        self.dropped += max(0, len(s) - max(room, 0))
        return len(s)

    def getvalue(self) -> str:
        return "".join(self.parts)


# A case's limit counts the CPU time of the thread that runs the learner's code, so an honest answer
# is not cut off because the machine is busy (a class graded side by side, CI beside other jobs). The
# calling thread takes its share of multi-threaded numpy/torch work, so on an idle machine this is the
# wall clock. Code that waits without computing (sleep, input, a lock, a busy helper thread) is stopped
# by the wall clock at WALL_FACTOR times the limit (generous: on a machine loaded ten times over,
# honest code gets a tenth of a core).
WALL_FACTOR = 10.0
POLL_S = 0.02


@contextlib.contextmanager
def _time_limit(seconds: float | None):
    usable = (seconds is not None and seconds > 0 and hasattr(time, "pthread_getcpuclockid")
              and threading.current_thread() is threading.main_thread())
    if not usable:
        yield
        return
    me = threading.get_ident()
    clock = time.pthread_getcpuclockid(me)
    cpu0, wall0 = time.clock_gettime(clock), time.monotonic()
    done, why = threading.Event(), []

    def watch() -> None:
        while not done.wait(POLL_S):
            cpu, wall = time.clock_gettime(clock) - cpu0, time.monotonic() - wall0
            if cpu >= seconds or wall >= WALL_FACTOR * seconds:
                why.append("cpu" if cpu >= seconds else "wall")
                signal.pthread_kill(me, signal.SIGALRM)
                return

    def _raise(signum, frame):
        if why and why[0] == "wall":
            raise TimeLimitExceeded(f"time limit exceeded: still running after {WALL_FACTOR * seconds:g} s "
                                    f"(waiting, not computing?)")
        raise TimeLimitExceeded(f"time limit of {seconds:g} s exceeded (counted in CPU time)")

    previous = signal.signal(signal.SIGALRM, _raise)
    watcher = threading.Thread(target=watch, name="cv3d-time-limit", daemon=True)
    watcher.start()
    try:
        yield
    finally:
        done.set()
        watcher.join()
        signal.signal(signal.SIGALRM, previous)


_COTANGENT: contextvars.ContextVar = contextvars.ContextVar("cotangent", default=None)


@contextlib.contextmanager
def backward_weights(L: np.ndarray):
    """The judge will call `(output * L).sum().backward()` on the tensor the learner's function returns.
    In graded mode the learner's code runs in another process and its autograd graph cannot cross, so
    the learner's side computes d(output · L)/d(inputs) and the judge gets a stand-in tensor with the same
    value and, for this L, the same gradients. Without isolation this changes nothing."""
    token = _COTANGENT.set(np.asarray(L, dtype=float))
    try:
        yield
    finally:
        _COTANGENT.reset(token)


def current_cotangent() -> np.ndarray | None:
    return _COTANGENT.get()


def _snapshot(x: Any) -> Any:
    try:
        return copy.deepcopy(x)
    except Exception:  # objects that cannot be copied are not checked for mutation
        return None


def _same(a: Any, b: Any) -> bool:
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (isinstance(a, np.ndarray) and isinstance(b, np.ndarray) and a.shape == b.shape
                and a.dtype == b.dtype and np.array_equal(a, b, equal_nan=True))
    if isinstance(a, (list, tuple)) and isinstance(b, (list, tuple)):
        return type(a) is type(b) and len(a) == len(b) and all(_same(u, v) for u, v in zip(a, b))
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if hasattr(a, "tocsr") and hasattr(b, "tocsr"):  # scipy.sparse: == would build a dense mask
        return a.shape == b.shape and (a != b).nnz == 0
    try:
        return bool(a == b)
    except Exception:
        return True


def _short_traceback(exc: BaseException) -> str:
    """The learner-facing part of a traceback: drop the frames that belong to this module."""
    frames = [f for f in traceback.extract_tb(exc.__traceback__) if f.filename != __file__]
    lines = traceback.format_list(frames[-4:]) + traceback.format_exception_only(type(exc), exc)
    return "".join(lines).rstrip()


def safe_call(fn: Callable, args: tuple = (), kwargs: dict | None = None,
              timeout: float | None = 10.0, names: tuple[str, ...] | None = None) -> Outcome:
    """Call `fn(*args, **kwargs)` and report what happened; never raises (but KeyboardInterrupt).

    names: argument names used when reporting a mutated input (defaults to arg0, arg1, ...).
    """
    kwargs = dict(kwargs or {})
    labels = list(names or ()) + [f"arg{i}" for i in range(len(names or ()), len(args))]
    before = [_snapshot(a) for a in args], {k: _snapshot(v) for k, v in kwargs.items()}
    out = Outcome()
    buffer = _CappedWriter(OUTPUT_CAP)
    start = time.perf_counter()
    try:
        with _time_limit(timeout), contextlib.redirect_stdout(buffer), contextlib.redirect_stderr(buffer):
            out.value = fn(*args, **kwargs)
    except KeyboardInterrupt:
        raise
    except NotImplementedError as exc:
        out.kind, out.error = "not_implemented", "not implemented yet (raises NotImplementedError)"
        out.traceback = _short_traceback(exc)
    except TimeLimitExceeded as exc:
        out.kind, out.error = "timeout", f"{exc}: an endless loop, or far too slow?"
    except SystemExit as exc:
        out.kind, out.error = "exit", f"called sys.exit({exc.code!r}); a function must return a value"
    except BaseException as exc:  # noqa: BLE001 — anything the learner raises is reported, not re-raised
        if hasattr(exc, "remote_kind"):   # graded mode: the learner's error, as its own process reported it
            out.kind, out.error, out.traceback = exc.remote_kind, exc.error, exc.traceback
        else:
            out.kind, out.error = "exception", f"raised {type(exc).__name__}: {exc}"
            out.traceback = _short_traceback(exc)
    out.seconds = time.perf_counter() - start
    out.stdout, out.stdout_truncated = buffer.getvalue(), buffer.dropped
    for label, old, new in zip(labels, before[0], args):
        if old is not None and not _same(old, new):
            out.mutated.append(label)
    for key, old in before[1].items():
        if old is not None and not _same(old, kwargs[key]):
            out.mutated.append(key)
    return out


# ------------------------------------------------------------------ files the learner's code writes for the judge

def learner_of(fn: Callable) -> Any:
    """The learner process behind a graded-mode function (graders.grading.isolation.RemoteFunction), or None."""
    return getattr(fn, "learner", None) or getattr(getattr(fn, "parent", None), "learner", None)


def restart_point(fn: Callable) -> Callable[[], Callable]:
    """For a case that stops the learner's program and runs it again (10.10: a client that crashed, then resumes):
    call it before the first run; `restart()` then gives the learner's function as a program started afresh would
    run it, so that only what the first run wrote to disk reaches the second (a module-level dict is no checkpoint).

    Graded mode: the learner's process is ended (its folders and files stay) and the next call starts a new one,
    which loads the learner's code again. Self-study, where the code runs in the judge's process: a copy of `fn`
    unpickled from a by-value pickle taken now (cloudpickle; its module's functions and classes by value), with its
    own copies of the module-level values it reaches as they are now. Not reset there (self-study is permissive):
    state held in other modules or in objects pickled by reference (an lru_cache); `fn` itself if it cannot be
    pickled (a global holding a lock)."""
    learner = learner_of(fn)
    if learner is not None:
        return lambda: (learner.stop(), fn)[1]
    frozen = _by_value(fn)
    if frozen is None:
        return lambda: fn
    import pickle
    return lambda: pickle.loads(frozen)


def _by_value(fn: Callable) -> bytes | None:
    """`fn` pickled by value with the module-level values it reaches, or None if it cannot be."""
    import sys
    try:
        import cloudpickle
        module = sys.modules.get(getattr(fn, "__module__", None) or "")
        register = (module is not None and module.__name__ not in ("__main__", "builtins")
                    and module.__name__ not in cloudpickle.list_registry_pickle_by_value())
        if register:
            cloudpickle.register_pickle_by_value(module)
        try:
            return cloudpickle.dumps(fn)
        finally:
            if register:
                cloudpickle.unregister_pickle_by_value(module)
    except Exception:     # noqa: BLE001 — not picklable (or no cloudpickle): the function as it is
        return None


@contextlib.contextmanager
def folder_for_learner(fn: Callable, prefix: str):
    """A fresh folder the learner's code may write into, removed afterwards. In graded mode it is owned by
    the learner's user inside its private folder (whose other entries it cannot touch); the judge reads
    what it left there only through `copy_out` / `read_text_no_link`, never following a link."""
    import shutil
    import tempfile
    learner = learner_of(fn)
    folder = learner.writable_folder(prefix) if learner is not None else tempfile.mkdtemp(prefix=prefix)
    try:
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def read_text_no_link(path: str, max_bytes: int = 256 << 20) -> str | None:
    """The text of a regular file the learner's code wrote (None if there is none); a link is not followed."""
    import os
    import stat
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK)
    except OSError:
        return None
    with os.fdopen(fd, "rb") as f:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        return f.read(max_bytes).decode("utf-8", errors="replace")


def copy_out(folder: str, dest: str, max_bytes: int = 256 << 20) -> None:
    """Copy the regular files the learner's code left in `folder` (its top level) into the judge's `dest`,
    opened relative to the folder's descriptor and never through a link."""
    import os
    import stat
    dfd = os.open(folder, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW)
    try:
        for name in os.listdir(dfd):
            try:
                fd = os.open(name, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK, dir_fd=dfd)
            except OSError:
                continue
            with os.fdopen(fd, "rb") as f:
                if not stat.S_ISREG(os.fstat(fd).st_mode):
                    continue
                data = f.read(max_bytes)
            with open(os.path.join(dest, name), "wb") as out:
                out.write(data)
    finally:
        os.close(dfd)
