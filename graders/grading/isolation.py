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

The learner process holds nothing graded work may not use: it runs an isolated interpreter (-I -S) from
a copy of `graders/grading/learner.py` and `graders/core/sandbox.py`, with the standard library and site-packages
only on its import path, a stand-in `graders`, no `solutions`, and the libraries its exercises may not
use (cv2, pycolmap, kornia for a from-scratch CODE exercise) as refusing stand-ins: one learner process
per library policy. Its environment is an allow-list. Where the OS allows it (Linux, as root,
util-linux `unshare`), it also gets its own PID, network, mount, UTS and IPC namespaces: the course
tree, `solutions`, the refused libraries, /root, /home, the grader's temp folders and the secret are
gone from its file system view, /tmp, /run and /dev/shm are its own (size-limited), everything else is
read-only but its private folder, a tmpfs of its disk quota (graders.grading.quota), and it runs as
`nobody` with no capabilities. As root without namespaces it still leaves root (graders.grading.users). Without namespaces (`process`
level) the files stay readable by the learner's code, so the judge adds a static check of the
learner's source (graders.grading.static_check) and says the isolation is weaker. `sandbox_level()` says
which level is in force; CV3D_SANDBOX=process forces the weaker one (to test it, or where namespaces
misbehave).
"""
from __future__ import annotations

import functools
import importlib.util
import json
import os
import pickle
import resource
import select
import shutil
import stat
import subprocess
import sys
import sysconfig
import tempfile
import threading
import time
from typing import Any, Callable

from graders.core.attempt import CaseReport
from graders.core.sandbox import TimeLimitExceeded, current_cotangent
from graders.grading.callbacks import MAX_CONCURRENT, CallbackServing
from graders.grading.learner import receive_bytes, send
from graders.grading import users
from graders.kit import datasets, diskcache
from graders.grading.processes import WALL_FACTOR, PidsLimit, die_with_parent
from graders.grading.policy import refusal
from graders.grading.quota import DISK_GB, POLL_S, DiskQuota, empty, unmount_stale
from graders.grading.transport import RemoteError, gradients_back, loads, swap_callables, tensors_back

MARGIN_S = 5.0          # the judge waits this much longer than the learner's own time limit
CPU_SECONDS = 1800      # CPU time of one learner process (it is restarted after every time-out)


# ------------------------------------------------------------------ the learner process

def sandbox_level() -> str:
    """"namespaces" (the learner's own file system view, no network, own PIDs, an unprivileged user) or
    "process" (its own process only; CV3D_SANDBOX=process chooses it)."""
    if (os.environ.get("CV3D_SANDBOX") == "process" or sys.platform != "linux" or os.geteuid() != 0
            or shutil.which("unshare") is None):
        return "process"
    probe = subprocess.run(["unshare", *UNSHARE, "true"],
                           capture_output=True, timeout=20)
    return "namespaces" if probe.returncode == 0 else "process"


UNSHARE = ("--pid", "--fork", "--kill-child", "--mount-proc", "--net", "--mount", "--uts", "--ipc",
           "--propagation", "private")
_LEVEL: str | None = None


def level() -> str:
    global _LEVEL
    if _LEVEL is None:
        _LEVEL = sandbox_level()
    return _LEVEL


def _limits(memory_gb: float, pids: PidsLimit, max_file_gb: float) -> Callable[[], None]:
    # Started by the judge's main thread (alive as long as the judge), the learner dies with a killed judge.
    arm = die_with_parent() if threading.current_thread() is threading.main_thread() else (lambda: None)

    def apply() -> None:   # in the child, between fork and exec
        arm()
        resource.setrlimit(resource.RLIMIT_AS, (int(memory_gb * 2**30),) * 2)
        resource.setrlimit(resource.RLIMIT_FSIZE, (int(max_file_gb * 2**30),) * 2)
        resource.setrlimit(resource.RLIMIT_CPU, (CPU_SECONDS, CPU_SECONDS))   # a backstop behind the time limits
        pids.enter()
    return apply


def _late(timeout: float, limit: float | None, waited: float, backstop: float | None) -> str:
    """Why the judge stopped waiting for an answer (`limit`: the case's, in CPU seconds; None: a plain wait)."""
    if limit is None:
        return f"time limit of {max(timeout - MARGIN_S, 0.05):.3g} s exceeded"
    if backstop is not None and waited >= backstop:
        return (f"time limit exceeded: no answer after {waited:.0f} s of wall-clock time, for a limit of {limit:g} s "
                "of CPU time (waiting, not computing?)")
    return f"time limit of {limit:g} s exceeded (counted in CPU time)"


ENV_KEPT = ("PATH", "LANG", "LC_ALL", "LC_CTYPE", "TZ", "OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
            "CV3D_LEARNER_STDERR")   # what the learner's environment keeps of the judge's: nothing else


def _learner_env(home: str, matplotlib: str | None = None) -> dict[str, str]:
    """An allow-list, not a deny-list: no token, socket, secret or seed of the instructor's reaches the learner."""
    env = {k: os.environ[k] for k in ENV_KEPT if k in os.environ}
    env.setdefault("PATH", "/usr/local/bin:/usr/bin:/bin")
    env.setdefault("OMP_NUM_THREADS", "1")
    env.update(HOME=home, TMPDIR=home, TMP=home, TEMP=home, MPLBACKEND="Agg", CV3D_NO_PROGRESS="1",
               PYTHONDONTWRITEBYTECODE="1")
    if matplotlib:
        env["MPLCONFIGDIR"] = matplotlib
    return env


def _font_cache() -> list[str]:
    """The judge's matplotlib font list (fontlist-v*.json in matplotlib's cache folder, found as matplotlib finds
    it, without importing it), if the judge's user wrote it and no one else may. A learner process starts with an
    empty home, where its notebook's `import matplotlib.pyplot` would rebuild that list by scanning every font on
    the machine (~0.4 CPU s per learner process); it gets a copy instead. Only font names and paths are in it."""
    folder = os.environ.get("MPLCONFIGDIR") or os.path.join(
        os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache"), "matplotlib")
    try:
        names = [n for n in os.listdir(folder) if n.startswith("fontlist-v") and n.endswith(".json")]
    except OSError:
        return []
    found = []
    for name in names:
        path = os.path.join(folder, name)
        try:
            st = os.lstat(path)
        except OSError:
            continue
        if stat.S_ISREG(st.st_mode) and st.st_uid == os.geteuid() and not st.st_mode & 0o022:
            found.append(path)
    return found


def _give_font_cache(folder: str, uid: int, gid: int) -> None:
    """Copies of the judge's font lists (`_font_cache`) in the learner's matplotlib folder (its MPLCONFIGDIR, in
    its private folder beside its home, which stays empty), owned by the learner. Best effort: without it (a quota
    smaller than the list, a file that went away) the learner's matplotlib builds its own."""
    for path in _font_cache():
        copy = os.path.join(folder, os.path.basename(path))
        try:
            shutil.copyfile(path, copy, follow_symlinks=False)
            os.chown(copy, uid, gid, follow_symlinks=False)
        except OSError:
            try:
                os.unlink(copy)
            except OSError:
                pass


def _record_paths(dist) -> list[list[str]]:
    """The parts of every path a distribution's RECORD lists ('' and '.' parts dropped, as PackagePath does), read as
    text: importlib.metadata's `files` makes a PackagePath of each of the ~20,000 lines of site-packages (1 CPU s)."""
    import csv
    text = dist.read_text("RECORD")
    if text is None:
        return [list(f.parts) for f in dist.files or ()]
    return [parts for row in csv.reader(text.splitlines()) if row
            if (parts := [p for p in row[0].split("/") if p not in ("", ".")])]


def _top_level(dist) -> set[str]:
    """The import names a distribution provides, as importlib.metadata.packages_distributions() finds them."""
    declared = (dist.read_text("top_level.txt") or "").split()
    if declared:
        return set(declared)
    return {parts[0] if len(parts) > 1 else parts[0][:-3] for parts in _record_paths(dist)
            if parts[-1].endswith(".py") and parts[-1] != ".py"}


@functools.lru_cache(maxsize=1)
def _packages_distributions() -> dict[str, list]:
    """Import name -> the installed distributions that provide it (as metadata.packages_distributions(), but
    the distributions, not their names), read once per judge process (0.08 CPU s; the standard library's takes
    0.39): the installed packages do not change while a grader runs."""
    import importlib.metadata as metadata
    found: dict[str, list] = {}
    for dist in metadata.distributions():
        for name in _top_level(dist):
            found.setdefault(name, []).append(dist)
    return found


@functools.lru_cache(maxsize=None)
def _distribution_folders(library: str) -> tuple[str, ...]:
    """Every top-level folder the installed distributions of `library` put in site-packages (cv2/,
    opencv_python_headless.libs/, its dist-info): hiding only the package would leave its binaries. Once per judge
    process and library (each learner process's start, and restart, hid them at 0.4 CPU s a library)."""
    folders = set()
    try:
        spec = importlib.util.find_spec(library)
    except (ImportError, ValueError):
        spec = None
    if spec is not None and spec.submodule_search_locations:
        folders |= {os.path.realpath(p) for p in spec.submodule_search_locations}
    for dist in _packages_distributions().get(library, []):
        tops = {parts[0] for parts in _record_paths(dist) if len(parts) > 1 and parts[0] != ".."}
        folders |= {os.path.realpath(str(dist.locate_file(top))) for top in tops}
    return tuple(sorted(folders))


CHECKOUT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))   # holds graders/


def _data_folders() -> list[str]:
    """$COURSE_DATA and the cache: datasets with their ground truth; the learner gets arrays or a file's copy."""
    return [p for p in (os.path.realpath(r) for r in datasets.roots()) if p != "/"]


def _course_roots() -> list[str]:
    """Folders that hold the course's packages (graders, solutions, benchmarks): this checkout, and any an
    editable install points to."""
    import importlib.util
    roots = {CHECKOUT}
    for name in ("solutions", "graders", "benchmarks"):
        try:
            spec = importlib.util.find_spec(name)
        except (ImportError, ValueError):
            spec = None
        for loc in (spec.submodule_search_locations or []) if spec else []:
            roots.add(os.path.dirname(os.path.realpath(loc)))
    for module in list(sys.modules.values()):
        mapping = getattr(module, "MAPPING", None) if getattr(module, "__name__", "").startswith("__editable__") else None
        for loc in (mapping or {}).values():
            roots.add(os.path.dirname(os.path.realpath(loc)))
    return sorted(roots)


def _site_packages() -> list[str]:
    import site
    return [p for p in site.getsitepackages() if os.path.isdir(p)]


PYTHON = sys.executable                 # the learner's interpreter
STDLIB = sorted({sysconfig.get_paths()["stdlib"], sysconfig.get_paths()["platstdlib"]})


def unprivileged_process_level() -> bool:
    """Process level as root (a container that refuses `unshare`): the learner still leaves root, if any user
    can run the interpreter (graders.grading.users); else it runs as root, and the isolation note says so."""
    return (level() == "process" and os.geteuid() == 0
            and users.others_can_read([PYTHON, *STDLIB, *_site_packages()]))


def learners_leave_this_user() -> bool:
    """Whether every learner process runs as a user other than the judge's (`nobody`, or a uid of its own): then
    the judge may read the disk cache's entries that only its own user can have written (diskcache.judge_only)."""
    return level() == "namespaces" or unprivileged_process_level()


class LearnerProcess(CallbackServing):
    """One learner process for one submission and one library policy: load its code once, then call its
    functions. `refused`: the libraries that are stand-ins there (all of LIBRARIES for a from-scratch CODE
    exercise). The folder it works in:

        private/            the judge's (read-only to the learner)
          runtime/          the learner process's own code (copies of learner.py and sandbox.py)
          from-the-grader/  the judge's temporary folders (cases that hand the learner files to read)
          home/             the learner's: its working folder, HOME and TMPDIR
    """

    def __init__(self, source: str, memory_gb: float = 8.0, max_processes: int = 256, max_file_gb: float = 1.0,
                 refused: tuple[str, ...] = ("cv2", "pycolmap", "kornia"), hide: tuple[str, ...] = (),
                 disk_gb: float | None = None):
        disk_gb = DISK_GB if disk_gb is None else disk_gb     # read at each start: a test lowers it
        self.source, self.memory_gb = source, memory_gb
        self.max_processes, self.max_file_gb = max_processes, min(max_file_gb, disk_gb)
        self.refused, self.extra_hidden = tuple(refused), tuple(hide)
        self.proc: subprocess.Popen | None = None
        self.problem, self.skipped = "", []
        self.level = level()
        self.private = tempfile.mkdtemp(prefix=f"cv3d-learner-{os.getpid()}-")   # its pid: see quota.unmount_stale
        self.drop = self.level == "process" and unprivileged_process_level() and users.open_the_way(self.private)
        os.chmod(self.private, 0o711 if self.drop else 0o755)    # other learners of a batch may not list it
        unmount_stale(os.path.dirname(self.private))
        # Everything the learner may write lives in here: the quota covers it (a tmpfs where we may mount).
        self.quota = DiskQuota(self.private, int(disk_gb * 2**30), mount=self.level == "namespaces")
        self._writable: list[str] = []
        self.uid, self.gid = (users.nobody() if self.level == "namespaces" else users.learner_ids() if self.drop
                              else (os.getuid(), os.getgid()))
        if self.uid == os.geteuid() and diskcache.mode() == "judge only":   # this learner could write the judge's
            diskcache.disable()                                            # files: no disk cache from now on
        self.home = self.writable_folder("home", exact=True)
        self.matplotlib = self.writable_folder("matplotlib", exact=True)     # its MPLCONFIGDIR
        _give_font_cache(self.matplotlib, self.uid, self.gid)
        self.exchange = os.path.join(self.private, "from-the-grader")
        os.mkdir(self.exchange, 0o755)
        self.runtime = os.path.join(self.private, "runtime")
        os.mkdir(self.runtime, 0o755)
        graders_dir = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
        for src, dst in (("grading/learner.py", "cv3d_learner.py"), ("core/sandbox.py", "cv3d_sandbox.py")):
            shutil.copyfile(os.path.join(graders_dir, src), os.path.join(self.runtime, dst))
        self.restarts = 0
        self._sending, self._slots = threading.Lock(), threading.BoundedSemaphore(MAX_CONCURRENT)

    def writable_folder(self, prefix: str, exact: bool = False) -> str:
        """A new folder inside the private folder that the learner's code may write (owned by its user)."""
        path = os.path.join(self.private, prefix) if exact else tempfile.mkdtemp(prefix=prefix, dir=self.private)
        if exact:
            os.mkdir(path, 0o700)
        self._writable.append(path)
        os.chown(path, self.uid, self.gid)
        os.chmod(path, 0o700)
        return path

    def _config(self, req_r: int, res_w: int) -> dict:
        hide = list(self.extra_hidden)
        if self.level == "namespaces":
            grades = os.path.dirname(os.path.dirname(os.path.dirname(self.private)))   # the grader's temp root
            hide += ["/root", "/home", "/autograder", "/etc/shadow", "/etc/gshadow", "/srv", "/mnt", "/media",
                     *_course_roots(), *(lib for name in self.refused for lib in _distribution_folders(name))]
            hide += _data_folders() + ([grades] if grades not in ("/", "") else [])
        # The test suite grading the course's own reference (and mutant catalogues) in graded mode, never
        # set to grade learners: this checkout's `solutions` and `tests/mutants` stay importable and visible.
        reference = os.environ.get("CV3D_GRADE_REFERENCE") == "1"
        keep = [os.path.realpath(p) for p in dict.fromkeys([sys.base_prefix, sys.prefix, *_site_packages(),
                                                             self.private])]
        # `solutions` where this interpreter finds it (the checkout, or the editable install behind an
        # autograder bundle, which has none of its own).
        spec = importlib.util.find_spec("solutions") if reference else None
        solutions_dir = os.path.dirname(spec.origin) if spec and spec.origin else os.path.join(CHECKOUT, "solutions")
        if reference:
            keep += [p for p in (solutions_dir, os.path.join(CHECKOUT, "tests", "mutants")) if os.path.isdir(p)]
        return {"fds": [req_r, res_w], "home": self.home, "writable": self.private, "lockdown": self.level == "namespaces",
                "refused": list(self.refused), "allow_solutions": reference, "site": _site_packages(),
                "extra_path": list(dict.fromkeys([CHECKOUT, os.path.dirname(solutions_dir)])) if reference else [],
                "hide": hide, "keep": keep,
                "uid": self.uid, "gid": self.gid, "drop": self.drop,
                # PID 1 under unshare, else the judge's thread that starts it (see `_limits`)
                "die_with_parent": self.level == "namespaces" or threading.current_thread() is threading.main_thread(),
                "tmpfs_mb": max(1, min(256, self.quota.limit >> 20))}   # /tmp, /dev/shm, ...: each within the quota

    # -- life cycle
    def start(self) -> None:
        req_r, req_w = os.pipe()
        res_r, res_w = os.pipe()
        config = self._config(req_r, res_w)
        # Imported by name (not run as __main__) so that its classes pickle by reference (a Dask pool in
        # the learner's code ships the grader's callbacks to its threads).
        boot = f"import sys; sys.path.append({self.runtime!r}); import cv3d_learner; cv3d_learner.main()"
        cmd = [PYTHON, "-I", "-S", "-c", boot, json.dumps(config)]
        if config["lockdown"]:
            cmd = ["unshare", *UNSHARE] + cmd
        self.pids = PidsLimit(self.max_processes)
        self.proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                                     stderr=None if os.environ.get("CV3D_LEARNER_STDERR") else subprocess.DEVNULL,
                                     pass_fds=(req_r, res_w), cwd=self.home,
                                     env=_learner_env(self.home, self.matplotlib), start_new_session=True,
                                     preexec_fn=_limits(self.memory_gb, self.pids, self.max_file_gb))
        os.close(req_r)
        os.close(res_w)
        self.req, self.res = req_w, res_r
        os.set_blocking(self.req, False)   # every write has a deadline: a learner that stops reading cannot block us
        self._write_by = time.monotonic() + 120.0
        try:
            reply = self._exchange({"op": "load", "source": self.source}, timeout=120.0)
            self.problem = "" if reply.get("ok") else reply.get("error", "your code failed to load")
            self.skipped = reply.get("skipped", [])
        except (RemoteError, TimeLimitExceeded) as exc:
            self.problem = f"your code failed to load: {exc}"
        self.residents = self.pids.members() | ({self.proc.pid} if self.proc else set())   # may live between calls

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
        self.quota.release()
        shutil.rmtree(self.private, ignore_errors=True)

    def check_quota(self) -> None:
        """Past its disk quota the learner is stopped, what it wrote is removed, and the call fails saying so."""
        if not self.quota.exceeded():
            return
        self.stop()
        for folder in self._writable:
            if os.path.isdir(folder) and not os.path.islink(folder):
                empty(folder)
        raise RemoteError("crash", self.quota.message())

    def _wait(self, deadline: float, watch: bool, later: Callable[[], float | None] | None = None) -> float:
        """Until the learner's next message starts, looking at its disk use meanwhile; returns the deadline, which
        `later()` may push back when it passes (None: it stands, and TimeoutError). Checked before every message,
        so a stream of callback requests cannot keep the call alive past it."""
        while True:
            if time.monotonic() >= deadline:
                pushed = later() if later else None
                if pushed is None:
                    raise TimeoutError
                deadline = pushed
            left = deadline - time.monotonic()
            if select.select([self.res], [], [], max(min(left, POLL_S), 0.0))[0]:
                return deadline
            if watch:
                self.check_quota()

    def cpu_seconds(self) -> float:
        """CPU time (user + system) the kernel has counted for the learner's processes (`PidsLimit.cpu_seconds`):
        read by the judge, never reported by the learner's code."""
        return 0.0 if self.proc is None else self.pids.cpu_seconds(self.proc.pid)

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
    def _exchange(self, request: dict, timeout: float, callbacks: list[Callable] | None = None,
                  cpu_budget: float | None = None, backstop: float | None = None, limit: float | None = None) -> dict:
        """Send a request; serve the learner's callbacks until its reply; raise on silence or death.

        `timeout` is wall-clock time; with `cpu_budget`, the wait goes on past it while the learner's processes
        have used less CPU than that since the request, up to `backstop` seconds of wall-clock time (`limit`: the
        case's limit, for the message)."""
        cpu0 = self.cpu_seconds() if cpu_budget is not None else 0.0
        start = time.monotonic()
        deadline, last = start + timeout, start + max(timeout, backstop or 0.0)
        self._write_by = last              # the judge's writes (this request, callback replies) wait that long at most
        try:
            with self._sending:
                send(self.req, request, deadline=last)
        except TimeoutError:
            raise TimeLimitExceeded(_late(timeout, limit, time.monotonic() - start, backstop)) from None
        except OSError:
            raise RemoteError("crash", self._death()) from None

        def later() -> float | None:
            if cpu_budget is None or backstop is None:
                return None
            now, used = time.monotonic(), self.cpu_seconds() - cpu0
            if used >= cpu_budget or now >= last:
                return None
            return min(now + max(cpu_budget - used, POLL_S), last)
        watch = request["op"] in ("load", "call")        # what runs the learner's code
        serving: list[threading.Thread] = []
        try:
            while True:
                try:
                    deadline = self._wait(deadline, watch, later)
                    reply = loads(receive_bytes(self.res, max(deadline, last)))   # a started message: to the end
                except TimeoutError:
                    raise TimeLimitExceeded(_late(timeout, limit, time.monotonic() - start, backstop)) from None
                except EOFError:
                    raise RemoteError("crash", self._death()) from None
                except (pickle.UnpicklingError, ValueError, TypeError, AttributeError, IndexError) as exc:
                    raise RemoteError("garbage", f"returned an object the grader cannot receive ({exc}): return "
                                                   "numpy arrays, numbers, strings, lists, tuples or dicts") from None
                if reply.get("op") != "callback":
                    if watch:
                        self.check_quota()
                    return reply
                try:
                    self._dispatch_callback(reply, callbacks or [], serving, deadline)
                except TimeoutError:       # it stopped reading the grader's replies
                    raise TimeLimitExceeded(_late(timeout, limit, time.monotonic() - start, backstop)) from None
        finally:
            self._join(serving, deadline)

    def _death(self) -> str:
        try:
            code = self.proc.wait(timeout=2) if self.proc else None
        except subprocess.TimeoutExpired:     # it closed its channel but lives on: end it
            self.stop()
            return "your code closed the grading channel"
        return f"your code stopped the grading process (exit status {code})"

    def _running(self) -> "LearnerProcess":
        if self.proc is None:
            self._restart()
        return self

    def names(self, wanted: list[str]) -> list[str]:
        return self._running()._exchange({"op": "names", "names": wanted}, timeout=30.0)["names"]

    def value(self, name: str) -> Any:
        return tensors_back(self._running()._exchange({"op": "value", "name": name}, timeout=30.0)["value"])

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
        self.case: tuple[float, float, float] | None = None     # (limit, CPU used, wall-clock start) of a case
        self._stdout, self._mutated, self._used = [], [], set()
        self.died = ""    # how its process ended, if a call ended it (os._exit, a crash): later calls fail at once

    def returned(self, handle: int) -> "RemoteFunction":
        """A function the learner's code returned: calling it runs it in the learner process; what it
        prints and calls is reported with the function that returned it."""
        return RemoteFunction(self.learner, f"{self.__name__}'s returned function", self.exercise, handle, self)

    def __call__(self, *args, **kwargs):
        owner = self.parent or self
        limit, cpu_used, wall0 = owner.case or (self.exercise.timeout, 0.0, time.monotonic())
        # What is left of the case's limit (CPU) and of its backstop (wall clock), the margin once per case
        timeout = max(limit - cpu_used, 0.05)
        cpu_left = max(limit + MARGIN_S - cpu_used, 0.05)
        wall_left = max(WALL_FACTOR * limit + MARGIN_S - (time.monotonic() - wall0), 0.05)
        table: list[Callable] = []
        request = {"op": "call", "name": self.__name__, "handle": self.handle, "args": swap_callables(args, table),
                   "kwargs": swap_callables(kwargs, table), "timeout": timeout, "names": self.exercise.arg_names,
                   "cotangent": current_cotangent()}
        if owner.died:                    # it ended its process on an earlier case: not again, not per case
            raise RemoteError("crash", f"{owner.died} (on an earlier case; this one was not run)")
        if self.learner.proc is None:     # another exercise's code ended it: a fresh process for this one
            self.learner._restart()
        cpu0 = self.learner.cpu_seconds()
        try:
            reply = self.learner._exchange(request, min(cpu_left, wall_left), table, cpu_budget=cpu_left,
                                           backstop=wall_left, limit=limit)
        except TimeLimitExceeded:
            self.learner._restart()       # it did not answer: a fresh process for the next case
            raise
        except RemoteError as exc:
            if exc.kind == "crash":       # a dead process: the next exercise that needs one starts it
                owner.died = exc.error
                self.learner.stop()
            elif exc.kind == "garbage":   # a channel that cannot be trusted now
                self.learner._restart()
            raise
        if self.learner.pids.kill_all_but(self.learner.residents):   # processes it started and left running
            reply.setdefault("stdout", "")
            reply["stdout"] += "\n[the grader stopped processes your code started and left running]"
        if owner.case:
            owner.case = (limit, cpu_used + max(self.learner.cpu_seconds() - cpu0, 0.0), wall0)
        owner._stdout.append(reply.get("stdout", ""))
        owner._mutated += reply.get("mutated", [])
        owner._used |= set(reply.get("used", []))
        kind = reply.get("kind")
        if kind == "ok":
            value = tensors_back(reply["value"], owner)
            if reply.get("grads") is not None:
                value = gradients_back(value, reply, args, request["cotangent"])
            return value
        if kind == "not_implemented":
            raise NotImplementedError
        if kind == "timeout":   # what the timed-out call left running (threads, children) goes with the process
            self.learner._restart()
            raise TimeLimitExceeded(reply.get("error") or "time limit exceeded")
        raise RemoteError(kind or "exception", reply.get("error", "failed"), reply.get("traceback", ""))

    def drain(self) -> tuple[str, list[str], list[str]]:
        """What the calls since the last drain printed and mutated, and every refused name this function's
        calls have reached so far: a run shared by several cases (engine.shared_run) is refused on each."""
        out = ("".join(self._stdout), list(dict.fromkeys(self._mutated)), sorted(self._used))
        self._stdout, self._mutated = [], []
        return out

    def begin_case(self, timeout: float) -> None:
        """Every call this case makes (and its returned functions make) shares `timeout` seconds of the
        learner's CPU time and WALL_FACTOR times that of wall-clock time."""
        self.case = (timeout, 0.0, time.monotonic())

    def end_case(self, exercise: Any) -> CaseReport:
        stdout, mutated, used = self.drain()
        return CaseReport(stdout=stdout, mutated=mutated, refusal=refusal(exercise, used))
