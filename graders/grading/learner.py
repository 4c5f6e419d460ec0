"""The learner's side of graded mode: a process that holds only the learner's code.

    python -I -S RUNTIME/cv3d_learner.py CONFIG_JSON      (started by graders.grading.isolation.LearnerProcess)

The judge sends requests — load this source, which names exist, give me this value, call this function
with these inputs — and this process answers with plain data. It never sees a case's expected value,
the seed, the grader's state or the results channel, so code that walks the call stack, patches numpy
or the engine, or writes fake results changes nothing but its own outputs.

From-scratch policy, enforced by absence: the interpreter starts isolated (-I -S) from a copy of this
file and of graders/core/sandbox.py, with an import path of the standard library and site-packages only.
`graders` is a stand-in whose `check`/`use`/`answer_key` do nothing (a notebook's own imports still
load) and whose every other name refuses to run; the libraries this process's exercises may not use
(cv2, pycolmap, kornia for a from-scratch CODE exercise) are stand-ins that refuse the same way;
`solutions` is not importable. Where the judge runs as root with namespaces, their files are also gone
from this process's view (see `_lock_down`), so undoing the import hook brings nothing back. What the
learner's code tried to use is reported only to explain a refusal; the judge never relies on it.
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
import threading
import time
import types
from typing import Any, Callable

_used: list[str] = []            # refused names the learner's code called during the current request
_safe_call: Callable | None = None   # graders.core.sandbox.safe_call, kept before `graders` is replaced


# ------------------------------------------------------------------ framing (shared with the judge)

def send(fd: int, obj: Any, deadline: float | None = None) -> None:
    """One frame. With a deadline (time.monotonic()), on a non-blocking fd: TimeoutError when the reader has not
    taken it all by then (the judge's writes to a learner that stopped reading)."""
    data = pickle.dumps(obj, protocol=pickle.HIGHEST_PROTOCOL)
    view = memoryview(struct.pack("!Q", len(data)) + data)
    while view:
        if deadline is not None:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([], [fd], [], left)[1]:
                raise TimeoutError("the reader stopped reading")
        try:
            n = os.write(fd, view)
        except BlockingIOError:
            continue
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


# ------------------------------------------------------------------ what graded work cannot import

class GradedWorkRefusal(Exception):
    """Raised by every name of a module graded work may not use (a library the exercise is not allowed,
    the course's graders): the module is not in this process, only a stand-in that says so."""


def _refusal_text(name: str) -> str:
    if name.startswith("graders"):
        return (f"{name} is not available in graded work: the course's stand-ins and oracles are not an answer "
                "(self-study checks allow them)")
    return (f"{name} is not available here: this exercise is from scratch in graded work, so "
            f"{name.split('.')[0]} is not installed in the process that runs your code (self-study checks allow it)")


class _Refused:
    """What `cv2.projectPoints`, `graders.get` or `ch1._real.cv_undistort` is in the learner's process: any
    attribute is another refusal, a call raises. The real object was never loaded here."""
    __slots__ = ("_name",)

    def __init__(self, name: str):
        object.__setattr__(self, "_name", name)

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__") and attr.endswith("__"):
            raise AttributeError(attr)
        return _Refused(f"{self._name}.{attr}")

    def __call__(self, *args, **kwargs):
        _used.append(self._name)     # only for the message: the refusal itself does not depend on it
        raise GradedWorkRefusal(_refusal_text(self._name))

    def __mro_entries__(self, bases):
        _used.append(self._name)
        raise GradedWorkRefusal(_refusal_text(self._name))

    def __repr__(self) -> str:
        return f"<{self._name}: not available in graded work>"


class _StandInModule(types.ModuleType):
    """A refused module: importing it works (a notebook's imports still load), using it refuses."""

    def __init__(self, name: str):
        super().__init__(name, _refusal_text(name))
        self.__dict__["__path__"] = []          # a package: its submodules are stand-ins too

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__") and attr.endswith("__"):
            raise AttributeError(attr)
        if self.__name__.startswith("graders") and attr[:1].isupper() and attr.endswith(("Error", "Exception")):
            return _exception_class(attr)     # what the learner catches is not an answer
        return _Refused(f"{self.__name__}.{attr}")


_EXCEPTIONS: dict[str, type] = {}


def _exception_class(name: str) -> type:
    """The stand-in of a grader exception class (`ch10.TransientTaskError`): a real class, the same one
    whichever module path names it, raised when a grader callback fails with that class, so the learner's
    `except` clauses work."""
    if name not in _EXCEPTIONS:
        _EXCEPTIONS[name] = type(name, (RuntimeError,), {"__module__": "graders"})
    return _EXCEPTIONS[name]


def _graders_stand_in(name: str) -> types.ModuleType:
    """`graders` in the learner's process: `check` does nothing, `use` returns the learner's own function,
    `answer_key` says nothing; every other name (get, chapter packages, oracles, data loaders) refuses."""
    module = _StandInModule(name)
    if name == "graders":
        module.check = lambda *a, **k: None
        module.use = lambda exercise_id, attempt: attempt
        module.answer_key = lambda *a, **k: ""
    return module


class _Policy(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    """First on sys.meta_path: `graders` and the refused libraries load as stand-ins, `solutions` not at all.
    It only says what the learner may not have; the modules are also absent from the process's file
    system view where the OS allows it (graders.grading.isolation), so removing this finder brings nothing back."""

    def __init__(self, refused: tuple[str, ...], allow_solutions: bool):
        self.refused, self.allow_solutions = set(refused), allow_solutions

    def find_spec(self, fullname, path, target=None):
        top = fullname.split(".")[0]
        if top == "graders" or top in self.refused:
            return importlib.util.spec_from_loader(fullname, self, is_package=True)
        if top == "solutions" and not self.allow_solutions:
            raise ModuleNotFoundError(f"No module named {fullname!r}: the reference answers are not part of "
                                      "graded work", name=fullname)
        return None

    def create_module(self, spec):
        return _graders_stand_in(spec.name)

    def exec_module(self, module):
        pass


# ------------------------------------------------------------------ requests and callbacks

_fds: tuple[int, int] = (-1, -1)     # (requests from the judge, responses to it)


# Callbacks from the learner's threads (a Dask pool) share the pipe without taking turns for a whole round trip:
# each request carries an id, the judge's reply the same id, and whichever waiting thread is free reads the next
# frame and hands it to its owner (a reply to the thread that asked, a request to the main loop). So calls from
# two threads can be in the judge at once, where the judge serves them concurrently if it chooses to (10.10's
# stages: concurrent tasks are what the judge observes there).
_sending = threading.Lock()
_inbox = threading.Condition()
_replies: dict[int, Any] = {}     # callback id -> the judge's reply, read by another thread
_requests: list = []              # the judge's requests read by a callback thread (a late straggler)
_reading = [False]                # a thread is reading the pipe now
_ids = iter(range(1, 1 << 62))


def _next_frame(wanted: int | None) -> Any:
    """The judge's reply to callback `wanted`, or (wanted None) the judge's next request: taken from what another
    thread has read, or read here if no other thread is reading."""
    while True:
        with _inbox:
            while True:
                if wanted is None and _requests:
                    return _requests.pop(0)
                if wanted is not None and wanted in _replies:
                    return _replies.pop(wanted)
                if not _reading[0]:
                    _reading[0] = True
                    break
                _inbox.wait()
        try:
            frame = pickle.loads(receive_bytes(_fds[0]))
        except BaseException:      # the pipe closed (or a time limit struck): the next waiter reads, and fails too
            with _inbox:
                _reading[0] = False
                _inbox.notify_all()
            raise
        with _inbox:
            _reading[0] = False
            if isinstance(frame, dict) and frame.get("op") == "reply":
                _replies[frame.get("id")] = frame
            else:
                _requests.append(frame)
            _inbox.notify_all()


def _receive() -> Any:
    return _next_frame(None)


def _ask_judge(request: dict, error: type = RuntimeError) -> Any:
    with _sending:
        request = dict(request, id=next(_ids))
        send(_fds[1], request)
    reply = _next_frame(request["id"])
    if not reply["ok"]:
        kind = _exception_class(reply["type"]) if reply.get("type") else error
        raise kind(f"the grader's callback failed on your inputs: {reply['error']}")
    return _unswap(reply["value"])


class _Callback:
    """A grader function passed as an input: calling it asks the judge to run it and waits for its answer.
    An object, not a closure, so a task scheduler can name it (Dask tokenizes the functions it runs)."""
    __slots__ = ("index",)

    def __init__(self, index: int):
        self.index = index

    def __call__(self, *args, **kwargs):
        return _ask_judge({"op": "callback", "index": self.index, "args": _plain(args), "kwargs": _plain(kwargs)})

    def __dask_tokenize__(self):
        return ("cv3d-grader-callback", self.index)

    def __eq__(self, other) -> bool:
        return isinstance(other, _Callback) and other.index == self.index

    def __hash__(self) -> int:
        return hash(("cv3d-grader-callback", self.index))


callback_proxy = _Callback


class _RemoteObject:
    """A grader object a case handed to the learner (a pipeline's stages): it stays in the judge; reading
    one of its public attributes asks the judge (methods come back as callbacks)."""
    __slots__ = ("_index",)

    def __init__(self, index: int):
        object.__setattr__(self, "_index", index)

    def __getattr__(self, attr: str) -> Any:
        if attr.startswith("__") and attr.endswith("__"):
            raise AttributeError(attr)
        return _ask_judge({"op": "callback", "index": self._index, "attr": attr, "args": (), "kwargs": {}},
                          AttributeError)

    def __eq__(self, other) -> bool:      # the sandbox compares a copy of the inputs after the call
        return isinstance(other, _RemoteObject) and other._index == self._index

    def __hash__(self) -> int:
        return hash(self._index)


def _unswap(obj: Any) -> Any:
    if isinstance(obj, dict):
        if set(obj) == {"__callback__"}:
            return callback_proxy(obj["__callback__"])
        if set(obj) == {"__object__"}:
            return _RemoteObject(obj["__object__"])
        return {k: _unswap(v) for k, v in obj.items()}
    if isinstance(obj, tuple):
        return tuple(_unswap(o) for o in obj)
    if isinstance(obj, list):
        return [_unswap(o) for o in obj]
    return obj


# ------------------------------------------------------------------ the request loop

def _load(source: str, namespace: dict) -> dict:
    """Run the learner's definitions, statement by statement: a statement that uses what graded work may
    not have (a constant from `datasets.available(...)`, a refused library) is skipped and noted, so the
    rest still loads; any other failure stops the load, as in self-study."""
    import ast
    skipped: list[str] = []

    def run() -> None:
        for stmt in ast.parse(source, "<your notebook>").body:
            try:
                exec(compile(ast.Module([stmt], []), "<your notebook>", "exec"), namespace)
            except GradedWorkRefusal as exc:
                skipped.append(f"line {stmt.lineno}: {exc}")
    outcome = _safe_call(run, timeout=60.0)
    if outcome.kind != "ok":
        return {"ok": False, "error": f"your code failed to load: {outcome.error}\n{outcome.traceback}".rstrip()}
    return {"ok": True, "skipped": skipped}


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


MS_RDONLY, MS_NOSUID, MS_NODEV, MS_REMOUNT, MS_BIND, MS_REC = 1, 2, 4, 32, 4096, 16384


def _mount(libc, src: bytes | None, target: str, fstype: bytes | None, flags: int, data: bytes | None = None) -> None:
    import ctypes
    if libc.mount(src, target.encode(), fstype, flags, data) != 0:
        raise OSError(ctypes.get_errno(), f"mount {target}")


def _hide(libc, path: str, size: str = "16k", mode: str = "755") -> None:
    """An empty file system over `path` (a tmpfs; /dev/null over a file): what was there is gone from this view."""
    if os.path.isdir(path):
        _mount(libc, b"tmpfs", path, b"tmpfs", MS_NOSUID | MS_NODEV, f"size={size},mode={mode}".encode())
    elif os.path.exists(path):
        _mount(libc, b"/dev/null", path, None, MS_BIND)


def _lock_down(config: dict) -> None:
    """Inside fresh mount/PID/network/UTS/IPC namespaces (see graders.grading.isolation), as root, before any learner
    code: every mount read-only but the learner's home; the course tree, `solutions`, the refused libraries,
    /root, /home, the grader's temp folders (other submissions) and the secret's folder replaced by empty
    file systems; private /tmp, /var/tmp, /run and /dev/shm (size-limited); then an unprivileged user with
    no capabilities, so none of it can be undone."""
    import ctypes
    libc = ctypes.CDLL(None, use_errno=True)
    libc.mount.argtypes = [ctypes.c_char_p, ctypes.c_char_p, ctypes.c_char_p, ctypes.c_ulong, ctypes.c_char_p]
    home, writable = config["home"], config["writable"]
    # The private folder stays a writable mount, but its user may write only where it owns the folder
    # (its home, the folders a case hands it to write in); the judge's own folders there are root's.
    _mount(libc, writable.encode(), writable, None, MS_BIND)
    with open("/proc/self/mountinfo") as f:
        points = [line.split()[4].replace("\\040", " ") for line in f]
    for point in sorted(set(points), key=len):
        if point.startswith(("/proc", "/sys", "/dev")) or point == writable:
            continue
        try:
            _mount(libc, None, point, None, MS_REMOUNT | MS_BIND | MS_RDONLY | (MS_REC if point == "/" else 0))
        except OSError:
            pass   # a mount that cannot be remounted (already read-only, or gone) stays as it is
    # What the learner keeps (python, its packages, its runtime, its home), held open by descriptor before
    # the folders around them are hidden, then bound back at the same paths.
    keep = [(path, os.open(path, os.O_PATH | os.O_DIRECTORY)) for path in config["keep"] + [writable]]
    inside_kept = lambda p: any(p != k and p.startswith(k.rstrip("/") + "/") for k, _ in keep)  # noqa: E731
    scratch = {"/tmp": "1777", "/var/tmp": "1777", "/dev/shm": "1777", "/run": "755"}
    for path in sorted(set(config["hide"]) | set(scratch), key=len):
        if not inside_kept(path):
            _hide(libc, path, f"{config['tmpfs_mb']}m" if path in scratch else "16k", scratch.get(path, "755"))
    for path, fd in keep:
        if not os.path.isdir(path):            # hidden with a folder around it: put it back
            os.makedirs(path, mode=0o755, exist_ok=True)
            _mount(libc, f"/proc/self/fd/{fd}".encode(), path, None, MS_BIND | MS_REC)
        os.close(fd)
    for path in sorted(set(config["hide"]), key=len):
        if inside_kept(path):                  # a refused library inside the packages folder, ...
            _hide(libc, path)
    host = b"learner"
    libc.sethostname(host, len(host))
    # An unprivileged user: it owns nothing but its home, so it can neither undo the mounts nor write the
    # cgroup that holds its process limit, nor read what root keeps private.
    _become(libc, config["uid"], config["gid"], config["die_with_parent"])
    os.chdir(home)


def _become(libc, uid: int, gid: int, die_with_parent: bool) -> None:
    """From root to `uid`/`gid` for good: no supplementary groups, no capabilities (bounding set dropped too),
    no-new-privileges (a setuid binary gives nothing back); with `die_with_parent`, killed when its parent ends."""
    PR_SET_NO_NEW_PRIVS, PR_CAPBSET_DROP, PR_SET_PDEATHSIG = 38, 24, 1
    libc.prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0)
    for cap in range(64):
        libc.prctl(PR_CAPBSET_DROP, cap, 0, 0, 0)
    os.setgroups([])
    os.setresgid(gid, gid, gid)
    os.setresuid(uid, uid, uid)                # from root to another uid: every capability is cleared
    if os.getuid() == 0 or os.geteuid() == 0:
        raise SystemExit("could not leave root")
    if die_with_parent:                        # the uid change cleared PR_SET_PDEATHSIG (prctl(2)): set it again
        libc.prctl(PR_SET_PDEATHSIG, 9, 0, 0, 0)


def _python_path(config: dict) -> None:
    """The learner's import path: the standard library (already there: the interpreter runs with -I -S),
    the site-packages folders, nothing of the course."""
    runtime = os.path.dirname(os.path.abspath(__file__))     # this file and its copy of sandbox.py
    sys.path[:] = [p for p in sys.path if p] + config["site"] + [runtime] + config.get("extra_path", [])


def main() -> None:
    import json
    config = json.loads(sys.argv[1])
    request_fd, response_fd = config["fds"]
    if config["lockdown"]:
        _lock_down(config)
    else:
        if config.get("drop"):                 # process level as root (a container without unshare): not root
            import ctypes
            _become(ctypes.CDLL(None, use_errno=True), config["uid"], config["gid"], config["die_with_parent"])
        os.chdir(config["home"])
    # The learner's prints are captured per call; anything written at the C level goes nowhere.
    devnull = os.open(os.devnull, os.O_WRONLY)
    os.dup2(devnull, 1)
    if not os.environ.get("CV3D_LEARNER_STDERR"):   # set to see the learner process's own errors
        os.dup2(devnull, 2)
    os.environ["MPLBACKEND"] = "Agg"
    _python_path(config)
    global _safe_call
    from cv3d_sandbox import safe_call       # graders/core/sandbox.py, copied beside this file by the judge
    _safe_call = safe_call
    for name in [m for m in sys.modules if m.split(".")[0] in ("graders", "solutions", *config["refused"])]:
        del sys.modules[name]                  # none: this interpreter imported nothing of them
    sys.meta_path.insert(0, _Policy(tuple(config["refused"]), config.get("allow_solutions", False)))
    serve(request_fd, response_fd)


if __name__ == "__main__":
    main()
