"""Attacks on graded mode, each reproduced from issue 29 and each a regression test.

Every test runs the learner's code the way the shell grader's worker does (`graders.grading.worker._Graded`,
one isolated learner process per library policy) in both protection levels: `namespaces` (root with
Linux namespaces: the forbidden files are gone from the learner's view, it runs as `nobody`) and
`process` (what a non-root instructor or a container without `unshare` gets: stand-ins for the forbidden
modules and a static check of the source, results marked "weaker isolation"). Library-backed and
stand-in answers must score 0 in both; the sandbox's own walls are checked where they exist.
"""
from __future__ import annotations

import importlib.util
import os
import socket
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest

from graders.grading import isolation, processes, worker
from graders.core.engine import Case, Exercise, get, shared_run, with_file
from graders.grading.isolation import sandbox_level

LEVELS = ["namespaces", "process"]
NAMESPACES = sandbox_level() == "namespaces"
HEADER = "import numpy as np\nfrom graders import check, use, answer_key\nfrom graders import ch01_camera_models as ch1\n"


@pytest.fixture(params=LEVELS)
def level(request, monkeypatch):
    if request.param == "namespaces" and not NAMESPACES:
        pytest.skip("this machine cannot give the learner namespaces (needs Linux, root and util-linux unshare)")
    monkeypatch.setattr(isolation, "_LEVEL", request.param)
    monkeypatch.setattr(tempfile, "tempdir", tempfile.tempdir)   # the judge points it at the learner's folder
    return request.param


def judge(source: str, ids: list[str], seed: int = 7) -> dict:
    """Results of `ids` for `source`, as the worker grades them in graded mode."""
    exercises = [get(i) for i in ids]
    graded = worker._Graded(source, exercises)
    try:
        return {ex.id: worker.judge_one(graded, ex, seed) for ex in exercises}
    finally:
        graded.close()


def text(result) -> str:
    return str(result)


def assert_zero(results: dict, level: str, why: str = "") -> None:
    for i, r in results.items():
        assert r.score == 0, f"{i} scored {r.score}/{r.max_score} in {level} mode:\n{text(r)[:1500]}"
        if why:
            assert why in text(r) or (level == "process" and "weaker isolation" in text(r)), text(r)[:1500]


# ------------------------------------------------------------------ item 1: library answers

CV2_AFTER_CHAPTER_IMPORT = HEADER + '''
def project_points(X, K, R, t, dist=None):
    import cv2     # the chapter import above loaded the real cv2 before the hook watched it (issue 29, 1)
    d = np.zeros(5) if dist is None else np.asarray(dist, float)
    uv, _ = cv2.projectPoints(np.asarray(X, float).reshape(-1, 1, 3), cv2.Rodrigues(np.asarray(R, float))[0],
                              np.asarray(t, float).reshape(3, 1), np.asarray(K, float), d)
    return uv.reshape(-1, 2)
'''


def test_cv2_after_the_chapter_import_scores_nothing(level):
    assert_zero(judge(CV2_AFTER_CHAPTER_IMPORT, ["1.5"]), level, "from scratch")


# ------------------------------------------------------------------ item 2: six bypasses of the from-scratch record

BYPASSES = {
    "wrapped_real": HEADER + '''
from graders import get
def undistort_points(uv, K, dist):
    return get("1.6").fallback.__wrapped_real__(uv, K, dist)
''',
    "cleared_record": HEADER + '''
import __main__
def undistort_points(uv, K, dist):
    out = ch1.cv_undistort(uv, K, dist)
    del __main__._used[:]
    return out
''',
    "finder_removed": HEADER + '''
import sys
def undistort_points(uv, K, dist):
    sys.meta_path[:] = [f for f in sys.meta_path if "Policy" not in type(f).__name__ and "Finder" not in type(f).__name__]
    for name in [m for m in sys.modules if m.startswith("graders")]:
        del sys.modules[name]
    sys.path += ["%ROOT%"]
    import graders.ch01_camera_models as real
    return real.cv_undistort(uv, K, dist)
''',
    "solutions": HEADER + '''
from solutions.ch01_camera_models import undistort_points
''',
    "patched_send": HEADER + '''
import __main__
_send = __main__.send
def _quiet(fd, obj):
    if isinstance(obj, dict):
        obj["used"] = []
    return _send(fd, obj)
__main__.send = _quiet
def undistort_points(uv, K, dist):
    return ch1.cv_undistort(uv, K, dist)
''',
    "chapter_real": HEADER + '''
def undistort_points(uv, K, dist):
    return ch1._real.cv_undistort(uv, K, dist)
''',
}


@pytest.mark.parametrize("attack", sorted(BYPASSES))
def test_from_scratch_bypasses_score_nothing(attack, level):
    root = str(Path(__file__).resolve().parents[2])
    assert_zero(judge(BYPASSES[attack].replace("%ROOT%", root), ["1.6"]), level)


def test_forbidden_files_are_absent_from_the_learner_view(monkeypatch):
    """Namespaces: removing every import hook and reading the files by hand finds nothing to load."""
    if not NAMESPACES:
        pytest.skip("needs namespaces")
    monkeypatch.setattr(isolation, "_LEVEL", "namespaces")
    import cv2
    import solutions
    paths = [os.path.dirname(cv2.__file__), os.path.dirname(solutions.__file__), os.path.dirname(isolation.__file__)]
    source = f"import os\ndef probe():\n    return [os.listdir(p) if os.path.isdir(p) else None for p in {paths!r}]\n"
    with isolation.LearnerProcess(source) as learner:
        seen = learner.function("probe", get("1.5"))()
    assert all(not listing for listing in seen), seen


def test_the_datasets_and_their_ground_truth_are_absent_from_the_learner_view(monkeypatch):
    """Namespaces: $COURSE_DATA (real pairs with their ground truth) is hidden; a file an exercise reads (5.5's
    BAL problem, 6.8's g2o graphs) reaches the learner as a copy in its exchange folder (engine.with_file)."""
    from graders.kit import datasets
    if not NAMESPACES or not datasets.roots():
        pytest.skip("needs namespaces and a data folder")
    data = datasets.roots()[0]
    file = min((p for p in data.rglob("*") if p.is_file() and p.stat().st_size < 1 << 20), key=lambda p: str(p))
    monkeypatch.setattr(isolation, "_LEVEL", "namespaces")
    source = ("import os\ndef probe(path):\n    return [os.listdir(%r), os.path.exists(%r), open(path, 'rb').read()]\n"
              % (str(data), str(file)))
    with isolation.LearnerProcess(source) as learner:
        probe = learner.function("probe", get("1.5"))
        monkeypatch.setattr(tempfile, "tempdir", learner.exchange)   # as the judge does for each exercise
        monkeypatch.setattr(tempfile, "mkdtemp", tempfile.mkdtemp)
        worker._judge_folders_readable_by(learner)
        seen = with_file("problem.txt", file)(probe)
    assert seen[:2] == [[], False] and seen[2] == file.read_bytes(), (file, seen[:2])


def test_the_hidden_library_folders_are_what_importlib_metadata_lists():
    """The judge reads site-packages' RECORD files as text (isolation._record_paths, 0.09 CPU s a judge process against
    0.53): the import names are packages_distributions()'s, and each refused library's hidden folders are every top
    folder of its distributions' files (its package, its .libs with the binaries, its dist-info)."""
    import importlib.metadata as metadata
    from graders.core.engine import LIBRARIES
    found = isolation._packages_distributions()
    assert {name: [d.metadata["Name"] for d in dists] for name, dists in found.items()} == metadata.packages_distributions()
    for library in LIBRARIES:
        expected = {os.path.realpath(p) for p in importlib.util.find_spec(library).submodule_search_locations}
        for name in metadata.packages_distributions()[library]:
            expected |= {os.path.realpath(os.path.join(str(f.locate())[:-len(str(f))], f.parts[0]))
                         for f in metadata.distribution(name).files if len(f.parts) > 1 and f.parts[0] != ".."}
        assert isolation._distribution_folders(library) == tuple(sorted(expected)), library
    assert any(p.endswith(".libs") for p in isolation._distribution_folders("cv2"))    # the binaries, not only cv2/

# ------------------------------------------------------------------ item 5: stand-in answers, value questions, shared runs

STAND_INS = HEADER + '''
from graders import get
from graders.ch01_camera_models import cv_project as project_points
def fisheye_project(X_c, K, D):                      # _cheat_fallback: the registered stand-in as the answer
    return get("1.7").fallback(X_c, K, D)
pixel_1_1 = get("1.1").cases(None)[0].expected       # a value question answered by the grader's own case
'''


def test_stand_ins_and_the_graders_expected_values_score_nothing(level):
    results = judge(STAND_INS, ["1.1", "1.5", "1.7"])
    assert_zero(results, level)
    assert results["1.1"].status == "not_attempted", text(results["1.1"])   # the line never produced a value


def test_a_shared_run_is_refused_on_every_case(level, monkeypatch):
    """Several cases judging one run of the learner's code (engine.shared_run): a library call in that run
    costs every case, not only the first (issue 29, item 5: 4.14, 4.16, 4.17, 3.13-3.16)."""
    def cases(rng):
        run = shared_run(lambda fn: fn(np.arange(3.0)))
        return [Case(f"view {k}", (), np.arange(3.0) * 2, lambda a, b: float(np.abs(np.asarray(a) - b).max()), 1e-9,
                     call=run) for k in range(3)]
    ex = Exercise(id="1.5", title="shared run", name="double", kind="code", points=3, cases=cases)
    get("1.5")          # chapter 1 registered first, so that ours replaces its 1.5 for this test
    monkeypatch.setitem(__import__("graders.core.engine", fromlist=["_REGISTRY"])._REGISTRY, "1.5", ex)
    source = ("def double(x):\n    try:\n        import cv2\n        return cv2.addWeighted(x, 1.0, x, 1.0, 0.0).ravel()\n"
              "    except Exception:\n        return x * 2\n")
    result = judge(source, ["1.5"])["1.5"]
    assert result.score == 0, text(result)
    if level == "namespaces":      # (process mode: the static check refuses the import before any case runs)
        assert len(result.cases) == 3 and all("from scratch" in c.message for c in result.cases), text(result)


# ------------------------------------------------------------------ item 2 of the brief: secret, environment, sandbox walls

PROBE = '''
import os, socket, glob
def probe(abstract, unix_path, secret_path):
    out = {"uid": os.getuid(), "env": sorted(os.environ), "host": socket.gethostname()}
    with open("/proc/self/status") as f:
        out["caps"] = [l.split()[1] for l in f if l.startswith("CapEff")][0]
    for name, address in (("abstract", "\\0" + abstract), ("unix", unix_path)):
        s = socket.socket(socket.AF_UNIX)
        try:
            s.connect(address)
            out[name] = "connected"
        except OSError as e:
            out[name] = type(e).__name__
    try:
        out["secret"] = open(secret_path).read()
    except OSError as e:
        out["secret"] = type(e).__name__
    out["seeds"] = [p for p in glob.glob("/proc/[0-9]*/environ") if _has(p, b"CV3D_HIDDEN_SEEDS")]
    try:
        socket.sethostname("pwned")
        out["sethostname"] = "changed"
    except OSError as e:
        out["sethostname"] = type(e).__name__
    for path in glob.glob("/sys/fs/cgroup/pids/cv3d-learner-*/pids.max") + glob.glob("/sys/fs/cgroup/cv3d-learner-*/pids.max"):
        try:
            open(path, "w").write("100000")
            out["pids.max"] = "raised"
        except OSError as e:
            out["pids.max"] = type(e).__name__
    try:
        open("/dev/shm/" + abstract, "w").write("x")
    except OSError:
        pass
    return out

def _has(path, needle):
    try:
        return needle in open(path, "rb").read()
    except OSError:
        return False
'''


def test_the_learner_sees_no_secret_socket_or_instructor_environment(tmp_path, monkeypatch):
    monkeypatch.setenv("INSTRUCTOR_API_TOKEN", "tok-123")
    monkeypatch.setenv("SSH_AUTH_SOCK", str(tmp_path / "agent.sock"))
    monkeypatch.setenv("CV3D_GRADING_SECRET", "s3cret")
    abstract = f"cv3d-attack-{os.getpid()}"
    listeners = [socket.socket(socket.AF_UNIX), socket.socket(socket.AF_UNIX)]
    listeners[0].bind("\0" + abstract)
    unix_path = f"/tmp/{abstract}.sock"      # a host socket in /tmp, where agents and X servers keep theirs
    listeners[1].bind(unix_path)
    for s in listeners:
        s.listen(1)
    secret = tmp_path / "secret"
    secret.write_text("s3cret")
    try:
        for level in ([LEVELS[0]] if NAMESPACES else []) + [LEVELS[1]]:
            monkeypatch.setattr(isolation, "_LEVEL", level)
            with isolation.LearnerProcess(PROBE, hide=(str(secret),)) as learner:
                seen = learner.function("probe", get("1.5"))(abstract, unix_path, str(secret))
            assert not {"INSTRUCTOR_API_TOKEN", "SSH_AUTH_SOCK", "CV3D_GRADING_SECRET"} & set(seen["env"]), seen
            if level == "namespaces":     # (as root without namespaces it could read every process's files)
                assert not seen["seeds"], seen
                assert seen["uid"] != 0 and int(seen["caps"], 16) == 0, seen
                assert seen["abstract"] != "connected" and seen["unix"] != "connected", seen
                assert seen["secret"] != "s3cret", seen
                assert seen["sethostname"] != "changed" and seen.get("pids.max") != "raised", seen
                assert not Path("/dev/shm", abstract).exists()
    finally:
        for s in listeners:
            s.close()
        os.unlink(unix_path)


def test_a_file_beyond_the_size_limit_cannot_be_written(level):
    source = ("def fill():\n    try:\n        with open('big', 'wb') as f:\n            f.write(b'x' * (4 << 20))\n"
              "        return 'written'\n    except OSError as e:\n        return type(e).__name__\n")
    with isolation.LearnerProcess(source, max_file_gb=1 / 1024) as learner:     # 1 MiB
        assert learner.function("fill", get("1.5"))() != "written"


# ------------------------------------------------------------------ item 3: the judge never follows the learner's links

SWAP = '''
import os, threading
def swap(exchange, target):
    """Replace the judge's exchange folder by a link to `target`, now and from a thread that keeps trying."""
    def attempt():
        try:
            os.rename(exchange, exchange + ".old")
        except OSError:
            pass
        try:
            os.symlink(target, exchange)
        except OSError:
            pass
    attempt()
    threading.Thread(target=lambda: [attempt() for _ in range(200)], daemon=True).start()
    return os.path.islink(exchange)
'''


def test_the_learner_cannot_swap_the_judges_folder_for_a_link(tmp_path, monkeypatch):
    if not NAMESPACES:
        pytest.skip("in process mode the learner runs as the grader's own user, who may write where the grader may")
    monkeypatch.setattr(isolation, "_LEVEL", "namespaces")
    monkeypatch.setattr(tempfile, "tempdir", tempfile.tempdir)
    canary = tmp_path / "canary"
    canary.mkdir()
    graded = worker._Graded(SWAP, [get("1.5")])
    try:
        learner = graded.process(get("1.5"))
        linked = learner.function("swap", get("1.5"))(learner.exchange, str(canary))
        time.sleep(0.2)
        with tempfile.TemporaryDirectory() as folder:       # what a case's oracle does (4.17 writes a model)
            Path(folder, "cameras.txt").write_text("judge")
        assert not linked and not os.path.islink(learner.exchange)
        assert list(canary.iterdir()) == []
    finally:
        graded.close()


def test_the_judge_reads_what_the_learner_wrote_without_following_its_links(tmp_path):
    """4.16 / 6.27 / 10.10 read back files the learner's code wrote: a link it left there (to a file only
    root may read, to the secret) is not followed."""
    from graders.core.sandbox import copy_out, read_text_no_link
    private = tmp_path / "private"
    private.mkdir()
    (tmp_path / "shadow").write_text("root's secret")
    (private / "cameras.txt").write_text("# a model")
    (private / "images.txt").symlink_to(tmp_path / "shadow")
    mine = tmp_path / "mine"
    mine.mkdir()
    copy_out(str(private), str(mine))
    assert sorted(p.name for p in mine.iterdir()) == ["cameras.txt"]
    assert read_text_no_link(str(private / "images.txt")) is None
    assert read_text_no_link(str(private / "cameras.txt")) == "# a model"


# ------------------------------------------------------------------ item 4 of the brief: deaths cost one restart, not one per case

def test_a_learner_that_ends_its_process_costs_one_start_not_one_per_case(level):
    source = "import os\ndef project_points(X, K, R, t, dist=None):\n    os._exit(3)\n" \
             "def undistort_points(uv, K, dist):\n    return uv\n"
    exercises = [get("1.5"), get("1.6")]
    graded = worker._Graded(source, exercises)
    try:
        dead = worker.judge_one(graded, exercises[0], 7, hidden_seed=8)
        learner = graded.process(exercises[0])
        assert dead.score == 0 and learner.restarts == 0, (learner.restarts, text(dead))
        assert all("exit status 3" in c.message for c in dead.cases), text(dead)
        alive = worker.judge_one(graded, exercises[1], 7)      # the next exercise gets a fresh process
        assert learner.restarts == 1 and len(alive.cases) > 1 and "exit status" not in text(alive), text(alive)
    finally:
        graded.close()


# ------------------------------------------------------------------ a busy machine is not the learner's fault

def test_a_correct_answer_late_on_a_busy_machine_keeps_its_points_and_waiting_still_ends(level):
    """CI failed 1.18 (30 s, the first `import torch` of its learner process) beside a venv being installed: the
    judge's limit was wall-clock time. It now counts the CPU time the kernel reports for the learner's processes;
    waiting (here: the learner stopped, as a starved process is) ends at WALL_FACTOR times the limit."""
    import signal
    import threading
    from types import SimpleNamespace
    from graders.core.sandbox import TimeLimitExceeded
    source = "import time\ndef quick(x):\n    return x + 1\ndef waits(x):\n    time.sleep(600)\n"
    ex = SimpleNamespace(id="t.1", timeout=1.0, arg_names=None)
    with isolation.LearnerProcess(source) as learner:
        pids = learner.pids.members() or processes.tree(learner.proc.pid)
        quick, stopped = learner.function("quick", ex), 1.0 + isolation.MARGIN_S + 1.0   # past the old wall limit
        quick.begin_case(ex.timeout)
        for pid in pids:
            os.kill(pid, signal.SIGSTOP)
        threading.Timer(stopped, lambda: [os.kill(pid, signal.SIGCONT) for pid in pids]).start()
        t0 = time.monotonic()
        assert quick(1) == 2 and time.monotonic() - t0 >= stopped - 0.5
        if level == "process":       # one level suffices for the wall-clock end: it does not read /proc
            learner._restart = learner.stop      # timed to the verdict, not to the fresh process after it
            waits = learner.function("waits", ex)
            waits.begin_case(ex.timeout)
            t0 = time.monotonic()
            with pytest.raises(TimeLimitExceeded, match="wall-clock"):
                waits(1)
            assert time.monotonic() - t0 < isolation.WALL_FACTOR * ex.timeout + isolation.MARGIN_S + 2.0


STARVED = """
import os, signal
from solutions.ch01_camera_models import project_points as _reference
def project_points(X, K, R, t, dist=None):
    if not os.environ.get("STOPPED_ONCE"):            # the first case: stopped for 6 s, as a starved worker is
        os.environ["STOPPED_ONCE"] = "1"
        if os.fork() == 0:
            import time
            time.sleep(6.0)
            os.kill(os.getppid(), signal.SIGCONT)
            os._exit(0)
        os.kill(os.getpid(), signal.SIGSTOP)
    return _reference(X, K, R, t, dist)
"""


def test_a_worker_starved_past_the_hard_limit_keeps_its_points(tmp_path):
    """The runner's per-exercise limit counts the CPU of the worker's process tree: a worker that gets no CPU for
    longer than the limit (here: stopped, as on a machine busy with a batch) is not killed before WALL_FACTOR times
    it. A worker that waits instead of computing still is: tests/grading/test_quota.py, test_hostile.py."""
    from graders.grading.runner import check_file
    source = tmp_path / "01_starved.py"
    source.write_text(STARVED)
    results, _ = check_file(source, seed=7, only=["1.5"], hard_limit=5.0)
    assert results[0].score == results[0].max_score, str(results[0])


HIDDEN_CPU = """
import os, signal, time
def work(x):
    signal.signal(signal.SIGCHLD, signal.SIG_IGN)     # children vanish unreaped: /proc keeps no trace of their CPU
    r, w = os.pipe()
    for _ in range(4):
        if os.fork() == 0:
            end = time.process_time() + 0.3
            while time.process_time() < end:
                pass
            os.write(w, b"x")
            os._exit(0)
    done = b""
    while len(done) < 4:                              # the main thread computes nothing, it waits for the burners
        done += os.read(r, 4)                         # (a fixed sleep was too short on a loaded machine)
    return x
"""


def test_cpu_of_children_that_vanish_unreaped_is_counted(level):
    """The judge counts the learner's CPU with a cgroup's CPU account, which keeps what its ended tasks used:
    summing /proc over live processes lost children whose parent ignores SIGCHLD (reviewer's finding)."""
    from types import SimpleNamespace
    ex = SimpleNamespace(id="t.2", timeout=20.0, arg_names=None)
    with isolation.LearnerProcess(HIDDEN_CPU) as learner:
        if learner.pids.cpu_path is None:
            pytest.skip("no CPU-accounting cgroup here: the /proc fallback cannot see these children")
        fn = learner.function("work", ex)
        fn.begin_case(ex.timeout)
        before = learner.cpu_seconds()
        assert fn(3) == 3
        assert learner.cpu_seconds() - before >= 1.0, learner.cpu_seconds() - before      # 4 x 0.3 s burnt
        account = learner.pids.cpu_path
    assert not os.path.exists(account), account          # the CPU account's cgroup goes with the learner


FLOOD = """
import sys
def flood(x):        # callback requests the judge must answer, and never a read of its replies
    channel = sys.modules["cv3d_learner"]
    for i in range(5000):
        channel.send(channel._fds[1], {"op": "callback", "index": 10**6, "args": (), "kwargs": {}, "id": 10**9 + i})
"""


def test_a_learner_that_stops_reading_cannot_block_the_judge():
    """Replies to its callback requests fill the pipe it never reads: the judge's writes have a deadline (they
    blocked it until the runner's 120 s kill, reviewer's finding), and the call ends at the case's backstop."""
    from types import SimpleNamespace
    from graders.core.sandbox import TimeLimitExceeded
    ex = SimpleNamespace(id="t.3", timeout=0.5, arg_names=None)
    with isolation.LearnerProcess(FLOOD) as learner:
        learner._restart = learner.stop          # timed to the verdict, not to the fresh process after it
        fn = learner.function("flood", ex)
        fn.begin_case(ex.timeout)
        t0 = time.monotonic()
        with pytest.raises(TimeLimitExceeded):
            fn(1)
        assert time.monotonic() - t0 < isolation.WALL_FACTOR * ex.timeout + isolation.MARGIN_S + 3.0


def test_hidden_seeds_reach_the_worker_through_a_pipe_not_its_environment_or_argv(tmp_path, monkeypatch):
    """A learner running as the grader's user could read /proc/<worker>/environ and every cmdline."""
    import subprocess
    from graders.grading import runner
    seen = {}

    class Recorder:
        def __init__(self, cmd, env, pass_fds, **kwargs):
            seen["cmd"], seen["env"] = cmd, env
            seen["seeds_fd"] = os.dup(int(cmd[cmd.index("--hidden-fd") + 1]))
    monkeypatch.setattr(subprocess, "Popen", Recorder)
    proc, fd = runner._worker(tmp_path / "learner.py", ["1.5"], 7, tmp_path, 1.0, True, {"1.5": 987654321})
    os.close(fd)
    with os.fdopen(seen["seeds_fd"], "rb") as f:
        assert f.read() == b'{"1.5": 987654321}'
    assert "987654321" not in " ".join(seen["cmd"]) and "987654321" not in " ".join(seen["env"].values())
    assert "CV3D_HIDDEN_SEEDS" not in seen["env"] and "CV3D_GRADING_SECRET" not in seen["env"]


def test_the_judges_arenot_dumpable():
    """PR_SET_DUMPABLE 0: a process of the same user cannot read their /proc/<pid>/environ, mem or fds."""
    import subprocess
    import sys
    code = ("from graders.grading.worker import not_dumpable; not_dumpable(); import ctypes; "
            "print(ctypes.CDLL(None).prctl(3, 0, 0, 0, 0))")     # PR_GET_DUMPABLE
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "0", out.stderr[-500:]
