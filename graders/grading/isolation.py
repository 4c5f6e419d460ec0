"""Graded mode: the learner's code runs in its own process; the judge keeps the cases.

`LearnerProcess` starts `graders.grading.learner` and talks to it over two pipes. A `RemoteFunction` looks
like the learner's function to the engine: calling it sends the case's inputs (copies) across, the
learner process runs the function under the sandbox (time limit, captured output, mutation check)
and sends back only the output, what it printed, which inputs it changed and which library functions
it called. The judge never runs learner code, so nothing the learner does can read `expected`,
patch the engine or numpy, reach the seed or the results channel.

Callbacks cross the other way: when a case passes grader functions to the learner (a RANSAC given
the grader's `solve` and `residuals`), the learner process calls them back through the pipe and the
judge runs them. Outputs are unpickled with an allow-list (numbers, strings, containers, numpy and
scipy.sparse arrays, tensors sent as arrays): a learner object cannot run code in the judge.

Where the OS allows it (Linux, as root, util-linux `unshare`), the learner process also gets its own
PID, network and mount namespaces: every file system is read-only but its private working folder, the
network is off, the judge's processes are invisible, and it drops every capability before loading
the learner's code. `sandbox_level()` says which protection is in force.
"""
from __future__ import annotations

import io
import os
import pickle
import resource
import select
import shutil
import subprocess
import sys
import tempfile
import time
from typing import Any, Callable

from graders.core.attempt import CaseReport
from graders.grading.learner import receive_bytes, send
from graders.grading.policy import refusal
from graders.core.sandbox import TimeLimitExceeded, current_cotangent

MARGIN_S = 5.0          # the judge waits this much longer than the learner's own time limit
CPU_SECONDS = 1800      # CPU time of one learner process (it is restarted after every time-out)


class RemoteError(Exception):
    """The learner's function failed in the learner process: kind (exception | exit | crash), the
    message and the learner's own traceback, reported by the sandbox as if it had happened here."""

    def __init__(self, kind: str, error: str, traceback: str = ""):
        super().__init__(error)
        self.kind, self.error, self.traceback = kind, error, traceback
        self.remote_kind = {"crash": "exit", "garbage": "exception"}.get(kind, kind)   # what graders.core.sandbox reports


# ------------------------------------------------------------------ what may come back

_ALLOWED = {
    ("builtins", n) for n in ("list", "tuple", "dict", "set", "frozenset", "complex", "slice", "range",
                              "bytearray", "object", "bool", "int", "float", "str", "bytes")
} | {
    ("collections", "OrderedDict"), ("copyreg", "_reconstructor"),
    ("numpy", "ndarray"), ("numpy", "dtype"), ("numpy.core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "_reconstruct"),
    ("numpy._core.multiarray", "scalar"), ("numpy._core.numeric", "_frombuffer"),
    ("numpy.core.numeric", "_frombuffer"),
}
class _Unpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        if ((module, name) in _ALLOWED or module.startswith("numpy.dtypes") and name[:1].isupper()
                or module.startswith("scipy.sparse._") and name.endswith(("_matrix", "_array"))):
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"{module}.{name}")


def _loads(data: bytes) -> Any:
    return _Unpickler(io.BytesIO(data)).load()


def _tensors_back(value: Any, parent: "RemoteFunction | None" = None) -> Any:
    """Arrays the learner process sent for torch tensors become tensors again; a function it returned
    becomes a handle that calls it there."""
    if isinstance(value, dict) and set(value) == {"__handle__"} and parent is not None:
        return parent.returned(value["__handle__"])
    if isinstance(value, dict) and "__tensor__" in value:
        import torch
        return torch.from_numpy(value["__tensor__"].copy())
    if isinstance(value, (list, tuple)):
        return type(value)(_tensors_back(v, parent) for v in value)
    if isinstance(value, dict):
        return {k: _tensors_back(v, parent) for k, v in value.items()}
    return value


def _with_gradients(value: Any, grads: list, args: tuple, cotangent: Any = None) -> Any:
    """A tensor equal to the learner's value whose gradients on the judge's own input tensors are the
    learner's: value + L/|L|² Σ <g_i, x_i − x_i.detach()>, with g_i = d(value · L)/dx_i computed on the
    learner's side (L = 1 for a scalar cost). Backward of (out · L).sum() then gives exactly g_i."""
    import torch
    flat = [a for arg in args for a in (arg if isinstance(arg, (list, tuple)) else [arg])]
    leaves = [a for a in flat if isinstance(a, torch.Tensor) and a.requires_grad]
    out = torch.as_tensor(value, dtype=leaves[0].dtype).reshape(value.shape)
    L = torch.ones((), dtype=out.dtype) if cotangent is None else torch.as_tensor(cotangent, dtype=out.dtype)
    first_order = sum((torch.as_tensor(g, dtype=x.dtype) * (x - x.detach())).sum()
                      for x, g in zip(leaves, grads) if g is not None)
    return out + L / (L * L).sum() * first_order


def _gradients_back(value: Any, reply: dict, args: tuple, cotangent: Any) -> Any:
    """Put the learner's gradients on the output they belong to: the value itself, or element `at` of it."""
    at = reply.get("grad_at")
    if at is None:
        return _with_gradients(reply["value"]["__tensor__"], reply["grads"], args, cotangent)
    parts = list(value)
    parts[at] = _with_gradients(reply["value"][at]["__tensor__"], reply["grads"], args, cotangent)
    return type(value)(parts)


# ------------------------------------------------------------------ callbacks into the judge

def _swap_callables(obj: Any, table: list[Callable]) -> Any:
    """Replace grader callables in the inputs (top level, containers, dict values) by callback handles."""
    if callable(obj) and not isinstance(obj, type) and not hasattr(obj, "__array__"):
        table.append(obj)
        return {"__callback__": len(table) - 1}
    if isinstance(obj, tuple):
        return tuple(_swap_callables(o, table) for o in obj)
    if isinstance(obj, list):
        return [_swap_callables(o, table) for o in obj]
    if isinstance(obj, dict):
        return {k: _swap_callables(v, table) for k, v in obj.items()}
    return obj


# ------------------------------------------------------------------ the learner process

def sandbox_level() -> str:
    """"namespaces" (read-only file systems, no network, own PIDs, no capabilities) or "process"."""
    if sys.platform != "linux" or os.geteuid() != 0 or shutil.which("unshare") is None:
        return "process"
    probe = subprocess.run(["unshare", "--pid", "--fork", "--mount-proc", "--net", "--mount", "true"],
                           capture_output=True, timeout=20)
    return "namespaces" if probe.returncode == 0 else "process"


_LEVEL: str | None = None


def _level() -> str:
    global _LEVEL
    if _LEVEL is None:
        _LEVEL = sandbox_level()
    return _LEVEL


PIDS_CGROUP = "/sys/fs/cgroup/pids"   # cgroup v1 pids controller (v2: the unified hierarchy's pids.max)


class _PidsLimit:
    """At most `n` processes and threads for one learner process and everything it starts: a cgroup
    where the OS offers one to us (a fork bomb then stays in its own box, also beside other
    submissions graded at the same time), else RLIMIT_NPROC (per user, so only a rough bound)."""

    def __init__(self, n: int):
        self.n, self.path = n, None
        for root in (PIDS_CGROUP, "/sys/fs/cgroup"):
            if os.path.exists(os.path.join(root, "cgroup.procs")) and os.access(root, os.W_OK):
                _remove_stale(root)
                path = os.path.join(root, f"cv3d-learner-{os.getpid()}-{id(self)}-{time.monotonic_ns()}")
                try:
                    os.mkdir(path)
                    with open(os.path.join(path, "pids.max"), "w") as f:
                        f.write(str(n))
                    self.path = path
                    break
                except OSError:
                    shutil.rmtree(path, ignore_errors=True)

    def enter(self) -> None:   # in the child, between fork and exec
        if self.path:
            with open(os.path.join(self.path, "cgroup.procs"), "w") as f:
                f.write(str(os.getpid()))
        else:
            try:
                resource.setrlimit(resource.RLIMIT_NPROC, (_processes_of_this_user() + self.n,) * 2)
            except (ValueError, OSError):
                pass

    def members(self) -> set[int]:
        try:
            with open(os.path.join(self.path, "cgroup.procs")) as f:
                return {int(p) for p in f.read().split()}
        except (OSError, TypeError):
            return set()

    def kill_all_but(self, keep: set[int]) -> int:
        """Stop the processes the learner's code started and left running; returns how many."""
        stray = 0
        for _ in range(200):          # until none is left: a fork bomb refills its slots as we kill
            extra = self.members() - keep
            if not extra:
                break
            for pid in extra:
                try:
                    os.kill(pid, 9)
                    stray += 1
                except OSError:
                    pass
            time.sleep(0.005)
        return stray

    def close(self) -> None:
        if not self.path:
            return
        for _ in range(100):          # kill until empty: a fork bomb keeps making new members
            try:
                with open(os.path.join(self.path, "cgroup.procs")) as f:
                    pids = [int(p) for p in f.read().split()]
            except OSError:
                break
            if not pids:
                break
            for pid in pids:
                try:
                    os.kill(pid, 9)
                except OSError:
                    pass
            time.sleep(0.02)
        for _ in range(50):           # members that were just killed take a moment to leave
            try:
                os.rmdir(self.path)
                break
            except OSError:
                time.sleep(0.02)
        self.path = None


def _remove_stale(root: str) -> None:
    """Empty cgroups of learner processes whose grader has ended (a killed grader cannot remove its own)."""
    for name in os.listdir(root):
        if not name.startswith("cv3d-learner-"):
            continue
        try:
            owner = int(name.split("-")[2])
            os.kill(owner, 0)              # the grader that made it is still running: leave it
        except ProcessLookupError:
            try:
                os.rmdir(os.path.join(root, name))
            except OSError:
                pass
        except (ValueError, IndexError, PermissionError):
            pass


def _limits(memory_gb: float, pids: _PidsLimit, max_file_gb: float) -> Callable[[], None]:
    def apply() -> None:   # in the child, between fork and exec
        resource.setrlimit(resource.RLIMIT_AS, (int(memory_gb * 2**30),) * 2)
        resource.setrlimit(resource.RLIMIT_FSIZE, (int(max_file_gb * 2**30),) * 2)
        resource.setrlimit(resource.RLIMIT_CPU, (CPU_SECONDS, CPU_SECONDS))   # a backstop behind the time limits
        pids.enter()
    return apply


def _processes_of_this_user() -> int:
    uid = os.getuid()
    count = 0
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            count += os.stat(f"/proc/{pid}").st_uid == uid
        except OSError:
            pass
    return count


class LearnerProcess:
    """One learner process for one submission: load its code once, then call its functions."""

    def __init__(self, source: str, memory_gb: float = 8.0, max_processes: int = 256, max_file_gb: float = 1.0):
        self.source, self.memory_gb = source, memory_gb
        self.max_processes, self.max_file_gb = max_processes, max_file_gb
        self.proc: subprocess.Popen | None = None
        self.problem = ""
        self.private = tempfile.mkdtemp(prefix="cv3d-learner-")
        self.restarts = 0

    # -- life cycle
    def start(self) -> None:
        req_r, req_w = os.pipe()
        res_r, res_w = os.pipe()
        lockdown = _level() == "namespaces"
        cmd = [sys.executable, "-m", "graders.grading.learner", str(req_r), str(res_w), self.private, str(int(lockdown))]
        if lockdown:
            cmd = ["unshare", "--pid", "--fork", "--kill-child", "--mount-proc", "--net", "--mount",
                   "--propagation", "private"] + cmd
        env = {k: v for k, v in os.environ.items() if not k.startswith(("COURSE_GRADING", "CV3D_SECRET"))}
        env.update(TMPDIR=self.private, TMP=self.private, TEMP=self.private, HOME=self.private, MPLBACKEND="Agg",
                   OMP_NUM_THREADS=env.get("OMP_NUM_THREADS", "1"))
        self.pids = _PidsLimit(self.max_processes)
        self.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=None if os.environ.get("CV3D_LEARNER_STDERR") else subprocess.DEVNULL,
                                     pass_fds=(req_r, res_w), cwd=self.private,
                                     env=env, start_new_session=True,
                                     preexec_fn=_limits(self.memory_gb, self.pids, self.max_file_gb))
        os.close(req_r)
        os.close(res_w)
        self.req, self.res = req_w, res_r
        try:
            reply = self._exchange({"op": "load", "source": self.source}, timeout=120.0)
            self.problem = "" if reply.get("ok") else reply.get("error", "your code failed to load")
        except (RemoteError, TimeLimitExceeded) as exc:
            self.problem = f"your code failed to load: {exc}"
        self.residents = self.pids.members() | {self.proc.pid}   # what may live between calls

    def stop(self) -> None:
        if self.proc is None:
            return
        for fd in (self.req, self.res):
            try:
                os.close(fd)
            except OSError:
                pass
        try:
            os.killpg(self.proc.pid, 9)
        except (ProcessLookupError, PermissionError):
            pass
        self.pids.close()
        self.proc.wait()
        self.proc = None

    def close(self) -> None:
        self.stop()
        shutil.rmtree(self.private, ignore_errors=True)

    def __enter__(self) -> "LearnerProcess":
        self.start()
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _restart(self) -> None:
        self.stop()
        self.restarts += 1
        self.start()

    # -- requests
    def _exchange(self, request: dict, timeout: float, callbacks: list[Callable] | None = None) -> dict:
        """Send a request; serve the learner's callbacks until its reply; raise on silence or death."""
        try:
            send(self.req, request)
        except (BrokenPipeError, OSError):
            raise RemoteError("crash", self._death()) from None
        deadline = time.monotonic() + timeout
        while True:
            try:
                reply = _loads(receive_bytes(self.res, deadline))
            except TimeoutError:
                raise TimeLimitExceeded(f"time limit of {max(timeout - MARGIN_S, 0.05):.3g} s exceeded") from None
            except EOFError:
                raise RemoteError("crash", self._death()) from None
            except (pickle.UnpicklingError, ValueError, TypeError, AttributeError, IndexError) as exc:
                raise RemoteError("garbage", f"returned an object the grader cannot receive ({exc}): return "
                                               "numpy arrays, numbers, strings, lists, tuples or dicts") from None
            if reply.get("op") != "callback":
                return reply
            self._serve_callback(reply, callbacks or [])

    def _serve_callback(self, request: dict, callbacks: list[Callable]) -> None:
        try:
            value = callbacks[request["index"]](*_tensors_back(request["args"]), **request["kwargs"])
            reply = {"ok": True, "value": value}
        except Exception as exc:   # the grader's callback failing on the learner's inputs: the learner's error
            reply = {"ok": False, "error": f"{type(exc).__name__}: {exc}"}
        send(self.req, reply)

    def _death(self) -> str:
        try:
            code = self.proc.wait(timeout=2) if self.proc else None
        except subprocess.TimeoutExpired:     # it closed its channel but lives on: end it
            self.stop()
            return "your code closed the grading channel"
        return f"your code stopped the grading process (exit status {code})"

    def names(self, wanted: list[str]) -> list[str]:
        return self._exchange({"op": "names", "names": wanted}, timeout=30.0)["names"]

    def value(self, name: str) -> Any:
        return _tensors_back(self._exchange({"op": "value", "name": name}, timeout=30.0)["value"])

    def function(self, name: str, exercise: Any) -> "RemoteFunction":
        return RemoteFunction(self, name, exercise)


class RemoteFunction:
    """The learner's function as the judge sees it (a `graders.core.attempt.RemoteAttempt`). After each case,
    `end_case` hands the engine what the learner printed, which inputs it changed, and graded mode's verdict
    (graders.grading.policy) on the library functions it called."""

    def __init__(self, learner: LearnerProcess, name: str, exercise: Any, handle: int | None = None,
                 parent: "RemoteFunction | None" = None):
        self.learner, self.__name__, self.exercise = learner, name, exercise
        self.handle, self.parent = handle, parent
        self.deadline: float | None = None
        self._stdout, self._mutated, self._used = [], [], set()

    def returned(self, handle: int) -> "RemoteFunction":
        """A function the learner's code returned: calling it runs it in the learner process; what it
        prints and calls is reported with the function that returned it."""
        return RemoteFunction(self.learner, f"{self.__name__}'s returned function", self.exercise, handle, self)

    def __call__(self, *args, **kwargs):
        timeout = self.exercise.timeout
        if self.deadline is not None:
            timeout = max(self.deadline - time.monotonic(), 0.05)
        table: list[Callable] = []
        owner = self.parent or self
        if self.parent is not None:
            self.deadline = self.parent.deadline
        request = {"op": "call", "name": self.__name__, "handle": self.handle, "args": _swap_callables(args, table),
                   "kwargs": _swap_callables(kwargs, table), "timeout": timeout, "names": self.exercise.arg_names,
                   "cotangent": current_cotangent()}
        try:
            reply = self.learner._exchange(request, timeout + MARGIN_S, table)
        except TimeLimitExceeded:
            self.learner._restart()       # it did not answer: a fresh process for the next case
            raise
        except RemoteError as exc:
            if exc.kind in ("crash", "garbage"):   # a dead process, or a channel that cannot be trusted now
                self.learner._restart()
            raise
        if self.learner.pids.kill_all_but(self.learner.residents):   # processes it started and left running
            reply.setdefault("stdout", "")
            reply["stdout"] += "\n[the grader stopped processes your code started and left running]"
        owner._stdout.append(reply.get("stdout", ""))
        owner._mutated += reply.get("mutated", [])
        owner._used |= set(reply.get("used", []))
        kind = reply.get("kind")
        if kind == "ok":
            value = _tensors_back(reply["value"], owner)
            if reply.get("grads") is not None:
                value = _gradients_back(value, reply, args, request["cotangent"])
            return value
        if kind == "not_implemented":
            raise NotImplementedError
        if kind == "timeout":   # what the timed-out call left running (threads, children) goes with the process
            self.learner._restart()
            raise TimeLimitExceeded(reply.get("error") or "time limit exceeded")
        raise RemoteError(kind or "exception", reply.get("error", "failed"), reply.get("traceback", ""))

    def drain(self) -> tuple[str, list[str], list[str]]:
        out = ("".join(self._stdout), list(dict.fromkeys(self._mutated)), sorted(self._used))
        self._stdout, self._mutated, self._used = [], [], set()
        return out

    def begin_case(self, timeout: float) -> None:
        self.deadline = time.monotonic() + timeout        # shared by every call this case makes

    def end_case(self, exercise: Any) -> CaseReport:
        stdout, mutated, used = self.drain()
        return CaseReport(stdout=stdout, mutated=mutated, refusal=refusal(exercise, used))
