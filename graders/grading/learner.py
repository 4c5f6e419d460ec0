"""The learner's side of graded mode: a process that holds only the learner's code.

    python -m graders.grading.learner REQUEST_FD RESPONSE_FD

The judge (`graders.grading.isolation.LearnerProcess`) sends requests — load this source, which names exist,
give me this value, call this function with these inputs — and this process answers with plain data.
It never sees a case's expected value, the seed, the grader's state or the results channel, so code
that walks the call stack, patches numpy or the engine, or writes fake results changes nothing but
its own outputs.

From-scratch policy: `cv2`, `pycolmap` and `kornia` are importable, but every call into them is
recorded and reported with the call's outcome; the judge decides, per exercise, whether it is allowed.
`graders` is replaced by a stand-in whose `check`/`use`/`answer_key` do nothing (a notebook's own
imports still load) and whose other names refuse to run: the course's stand-ins are not an answer.
"""
from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import os
import pickle
import select
import struct
import sys
import time
import types
from typing import Any, Callable

WATCHED = ("cv2", "pycolmap", "kornia")
_used: list[str] = []            # library calls made during the current request
_safe_call: Callable | None = None   # graders.core.sandbox.safe_call, kept before `graders` is replaced


# ------------------------------------------------------------------ framing (shared with the judge)

def send(fd: int, obj: Any) -> None:
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    view = memoryview(struct.pack("!Q", len(data)) + data)
    while view:
        n = os.write(fd, view)
        view = view[n:]


MAX_FRAME = 4 << 30     # bytes: a frame that claims more is not a frame


def _read_exact(fd: int, n: int, deadline: float | None) -> bytes:
    """Exactly n bytes from fd, by the deadline (time.monotonic()) if one is given."""
    chunks, left = [], n
    while left:
        if deadline is not None:
            ready, _, _ = select.select([fd], [], [], max(deadline - time.monotonic(), 0.0))
            if not ready:
                raise TimeoutError
        chunk = os.read(fd, min(left, 1 << 20))
        if not chunk:
            raise EOFError
        chunks.append(chunk)
        left -= len(chunk)
    return b"".join(chunks)


def receive_bytes(fd: int, deadline: float | None = None) -> bytes:
    """One frame: an 8-byte length, then that many bytes (the judge reads with a deadline: a learner
    process may write a header and stall)."""
    (n,) = struct.unpack("!Q", _read_exact(fd, 8, deadline))
    if n > MAX_FRAME:
        raise pickle.UnpicklingError(f"a frame of {n} bytes")
    return _read_exact(fd, n, deadline)


# ------------------------------------------------------------------ watched libraries

def _record(name: str, fn: Callable) -> Callable:
    def watched(*args, **kwargs):
        _used.append(name)
        return fn(*args, **kwargs)
    watched.__name__ = getattr(fn, "__name__", name)
    watched.__doc__ = getattr(fn, "__doc__", None)
    watched.__wrapped_real__ = fn
    return watched


class _WatchedModule(types.ModuleType):
    """A library module whose functions record their use (classes and constants pass through)."""

    def __init__(self, real: types.ModuleType, name: str):
        super().__init__(name)
        self.__dict__["_real"] = real

    def __getattr__(self, attr: str) -> Any:
        value = getattr(self.__dict__["_real"], attr)
        if attr.startswith("__"):
            return value
        full = f"{self.__name__}.{attr}"
        if isinstance(value, types.ModuleType):
            return _WatchedModule(value, full)
        if callable(value) and not isinstance(value, type):   # classes pass (isinstance, subclassing)
            return _record(full, value)
        return value

    def __dir__(self):
        return dir(self.__dict__["_real"])


WATCHED_GRADERS = ("graders.ch", "graders.oracles", "graders.kit.geometry", "graders.core.compare")


def _watched_name(fullname: str) -> bool:
    return ("." not in fullname and fullname in WATCHED) or fullname.startswith(WATCHED_GRADERS)


class _Finder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """Serves watched wrappers for cv2/pycolmap/kornia and for the graders' chapter packages, oracles
    and primitives (the course's own answers); data loaders and scene generators load as they are."""

    def find_spec(self, fullname, path, target=None):
        if _watched_name(fullname):
            return importlib.util.spec_from_loader(fullname, self, is_package=fullname.startswith("graders."))
        return None

    def create_module(self, spec):
        sys.meta_path.remove(self)
        try:
            real = importlib.import_module(spec.name)
        finally:
            sys.meta_path.insert(0, self)
        if spec.name.startswith("graders.ch"):
            _watch_fallbacks()
        for name in [m for m in sys.modules if m.startswith(spec.name + ".")]:   # its submodules, watched too
            if not isinstance(sys.modules[name], _WatchedModule):
                sys.modules[name] = _package_like(_WatchedModule(sys.modules[name], name), sys.modules[name])
        return _package_like(_WatchedModule(real, spec.name), real)

    def exec_module(self, module):
        pass


def _package_like(watched: "_WatchedModule", real: types.ModuleType) -> "_WatchedModule":
    if hasattr(real, "__path__"):
        watched.__dict__["__path__"] = real.__path__
    return watched


def _watch_fallbacks() -> None:
    """Every registered exercise's stand-in records its use, however the learner's code reaches it."""
    engine = sys.modules.get("graders.core.engine")
    for ex in getattr(engine, "_REGISTRY", {}).values():
        if ex.fallback is not None and not getattr(ex.fallback, "_cv3d_watched", False):
            ex.fallback = _record(f"graders stand-in of {ex.id}", ex.fallback)
            ex.fallback._cv3d_watched = True


def _graded_mode_graders() -> None:
    """In the learner's process `check` does nothing and `use` returns the learner's own function:
    demo helpers still load, but no course stand-in answers for the learner. The package is loaded already
    (this module is `graders.grading.learner`): it is patched, not imported from below."""
    graders = sys.modules["graders"]
    graders.check = lambda *a, **k: None
    graders.use = lambda exercise_id, attempt: attempt
    graders.answer_key = lambda *a, **k: ""


# ------------------------------------------------------------------ requests and callbacks

_fds: tuple[int, int] = (-1, -1)     # (requests from the judge, responses to it)


class _RequestUnpickler(pickle.Unpickler):
    """The judge's requests may hold objects of grader classes: find them under the names the real
    modules were moved to when `graders` was replaced by its stand-in."""

    def find_class(self, module: str, name: str):
        value = super().find_class(module, name)
        return getattr(value, "__wrapped_real__", value)


def _receive() -> Any:
    import io
    return _RequestUnpickler(io.BytesIO(receive_bytes(_fds[0]))).load()


def callback_proxy(index: int) -> Callable:
    """A grader function passed as an input: calling it asks the judge to run it and waits for its answer."""
    def callback(*args, **kwargs):
        send(_fds[1], {"op": "callback", "index": index, "args": _plain(args), "kwargs": _plain(kwargs)})
        reply = _receive()
        if not reply["ok"]:
            raise RuntimeError(f"the grader's callback failed on your inputs: {reply['error']}")
        return reply["value"]
    return callback


def _unswap(obj: Any) -> Any:
    if isinstance(obj, dict):
        if set(obj) == {"__callback__"}:
            return callback_proxy(obj["__callback__"])
        return {k: _unswap(v) for k, v in obj.items()}
    if isinstance(obj, tuple):
        return tuple(_unswap(o) for o in obj)
    if isinstance(obj, list):
        return [_unswap(o) for o in obj]
    return obj


# ------------------------------------------------------------------ the request loop

def _load(source: str, namespace: dict) -> dict:
    outcome = _safe_call(lambda: exec(compile(source, "<your notebook>", "exec"), namespace), timeout=60.0)
    if outcome.kind != "ok":
        return {"ok": False, "error": f"your code failed to load: {outcome.error}\n{outcome.traceback}".rstrip()}
    return {"ok": True}


def _call(namespace: dict, request: dict) -> dict:
    handle = request.get("handle")
    fn = namespace.get(request["name"]) if handle is None else _handles[handle]
    if not callable(fn):
        return {"kind": "exception", "error": f"`{request['name']}` is not a function", "traceback": ""}
    del _used[:]
    _reap()            # what the judge stopped after the previous call
    out = _safe_call(fn, _unswap(request["args"]), _unswap(request["kwargs"]), timeout=request["timeout"], names=request["names"])
    _reap()
    reply = {"kind": out.kind, "error": out.error, "traceback": out.traceback, "stdout": out.stdout,
             "stdout_truncated": out.stdout_truncated, "mutated": out.mutated, "used": sorted(set(_used))}
    if out.kind == "ok":
        reply["value"] = _plain(out.value)
        reply["grads"], reply["grad_at"] = _input_gradients(out.value, request["args"], request.get("cotangent"))
    return reply


def _reap() -> None:
    """Collect the children the learner's code left behind that have ended (zombies would hold the
    process budget); the judge stops those still running."""
    while True:
        try:
            pid, _ = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return


def _leaves(args: tuple) -> list:
    """The tensors among the inputs (top level, or inside a tuple/list argument) that require grad."""
    import torch
    flat = [a for arg in args for a in (arg if isinstance(arg, (list, tuple)) else [arg])]
    return [a for a in flat if isinstance(a, torch.Tensor) and a.requires_grad]


def _input_gradients(value: Any, args: tuple, cotangent: Any = None) -> tuple[list | None, int | None]:
    """d value / d input for a scalar tensor output with a graph (a differentiable cost), or d(value · L)/d
    input for a tensor output (or element `at` of a returned tuple) when the judge sent L: the judge
    rebuilds a first-order stand-in with the same value and the same gradients on its own inputs."""
    torch = sys.modules.get("torch")
    leaves = _leaves(args) if torch is not None else []
    if not leaves:
        return None, None
    candidates = [(None, value)] + (list(enumerate(value)) if isinstance(value, (list, tuple)) else [])
    for at, v in candidates:
        if not isinstance(v, torch.Tensor) or v.grad_fn is None:
            continue
        if cotangent is None and v.numel() == 1 and at is None:
            scalar = v.sum()
        elif cotangent is not None and tuple(v.shape) == tuple(cotangent.shape):
            scalar = (v * torch.as_tensor(cotangent, dtype=v.dtype)).sum()
        else:
            continue
        grads = torch.autograd.grad(scalar, leaves, allow_unused=True)
        return [None if g is None else g.detach().cpu().numpy() for g in grads], at
    return None, None


_handles: list[Callable] = []     # functions the learner's code returned (a trained descriptor, ...)


def _plain(value: Any) -> Any:
    """What crosses to the judge: torch tensors are sent as numpy arrays unless they carry a graph, in
    which case the gradient of a scalar with respect to the tensor inputs travels with its value."""
    if callable(value) and not isinstance(value, type) and not hasattr(value, "__array__"):
        _handles.append(value)                  # the judge calls it back through the channel
        return {"__handle__": len(_handles) - 1}
    torch = sys.modules.get("torch")   # a tensor exists only if the learner's code imported torch
    if torch is not None and isinstance(value, torch.Tensor):
        return {"__tensor__": value.detach().cpu().numpy(), "dtype": str(value.dtype).split(".")[-1],
                "requires_grad": bool(value.requires_grad)}
    if isinstance(value, (list, tuple)):
        return type(value)(_plain(v) for v in value)
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    return value


def _close_channel_in_child() -> None:
    """A process the learner's code forks must never speak on the channel (it would answer requests
    meant for this one): it loses both ends at birth."""
    for fd in _fds:
        try:
            os.close(fd)
        except OSError:
            pass


def serve(request_fd: int, response_fd: int) -> None:
    global _fds
    _fds = (request_fd, response_fd)
    os.register_at_fork(after_in_child=_close_channel_in_child)
    namespace: dict = {"__name__": "learner"}
    while True:
        try:
            request = _receive()
        except EOFError:
            return
        op = request["op"]
        if op == "load":
            reply = _load(request["source"], namespace)
        elif op == "names":
            reply = {"names": [n for n in request["names"] if n in namespace]}
        elif op == "value":
            reply = {"value": _plain(namespace.get(request["name"]))}
        elif op == "call":
            reply = _call(namespace, request)
        else:
            reply = {"error": f"unknown request {op!r}"}
        try:
            send(response_fd, reply)
        except (pickle.PicklingError, TypeError, AttributeError) as exc:
            send(response_fd, {"kind": "exception", "traceback": "",
                               "error": f"returned something that cannot be sent to the grader ({exc}); "
                                        "return numpy arrays, numbers, lists, tuples or dicts"})


def _lock_down(private: str) -> None:
    """Inside fresh mount/PID/network namespaces (see graders.grading.isolation): every mount but the private
    folder (and /proc, /sys, /dev) becomes read-only, then every capability is dropped, so the learner's
    code can neither undo it nor write anywhere else."""
    import ctypes
    libc = ctypes.CDLL(None, use_errno=True)
    MS_RDONLY, MS_REMOUNT, MS_BIND, MS_REC = 1, 32, 4096, 16384

    def mount(src, target, flags):
        if libc.mount(src, target.encode(), None, flags, None) != 0:
            raise OSError(ctypes.get_errno(), f"mount {target}")
    mount(private.encode(), private, MS_BIND)
    with open("/proc/self/mountinfo") as f:
        points = [line.split()[4].replace("\\040", " ") for line in f]
    for point in sorted(set(points), key=len):
        if point.startswith(("/proc", "/sys", "/dev")) or point == private:
            continue
        try:
            mount(None, point, MS_REMOUNT | MS_BIND | MS_RDONLY | (MS_REC if point == "/" else 0))
        except OSError:
            pass   # a mount that cannot be remounted (already read-only, or gone) stays as it is
    PR_SET_NO_NEW_PRIVS, PR_CAPBSET_DROP = 38, 24
    libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0)
    for cap in range(64):
        libc.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0)

    class Header(ctypes.Structure):
        _fields_ = [("version", ctypes.c_uint32), ("pid", ctypes.c_int)]

    class Data(ctypes.Structure):
        _fields_ = [("effective", ctypes.c_uint32), ("permitted", ctypes.c_uint32), ("inheritable", ctypes.c_uint32)]
    header, data = Header(0x20080522, 0), (Data * 2)()
    if libc.capset(ctypes.byref(header), data) != 0:
        raise OSError(ctypes.get_errno(), "capset")


def main() -> None:
    request_fd, response_fd = int(sys.argv[1]), int(sys.argv[2])
    private, lockdown = sys.argv[3], sys.argv[4] == "1"
    os.chdir(private)
    if lockdown:
        _lock_down(private)
    # The learner's prints are captured per call; anything written at the C level goes nowhere.
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    if not os.environ.get("CV3D_LEARNER_STDERR"):   # set to see the learner process's own errors
        os.dup2(devnull, 2)
    os.environ["MPLBACKEND"] = "Agg"
    global _safe_call
    from graders.core.sandbox import safe_call
    _safe_call = safe_call
    _graded_mode_graders()
    for name in [m for m in sys.modules if _watched_name(m)]:   # none yet; a fresh import goes through the finder
        del sys.modules[name]
    sys.meta_path.insert(0, _Finder())
    serve(request_fd, response_fd)


if __name__ == "__main__":
    main()
