"""The README's course command, `make lab`, starts JupyterLab as root or not, without a browser, and
serves the chapters; the test starts it the way the README does, asks it for the notebooks, stops it."""
from __future__ import annotations

import json
import os
import secrets
import signal
import socket
import subprocess
import time
import urllib.request
from pathlib import Path

from graders.core.chapters import READY

ROOT = Path(__file__).resolve().parents[2]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _lab(port: int, token: str, env: dict) -> subprocess.Popen:
    # port_retries=0: a port another process took since _free_port released it fails the server at once (with
    # the default 50 retries it would serve on another port and this test would poll the wrong one)
    return subprocess.Popen(["make", "lab", f"LAB_ARGS=--port={port} --ServerApp.port_retries=0 "
                             f"--IdentityProvider.token={token} --ip=127.0.0.1"],
                            cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True, text=True)


def _listing(proc: subprocess.Popen, port: int, token: str) -> dict | None:
    """The server's file listing, or None if it ended (its port taken) or did not answer in 90 s."""
    deadline = time.monotonic() + 90
    while time.monotonic() < deadline and proc.poll() is None:
        try:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/api/contents?token={token}", timeout=2) as r:
                return json.load(r)
        except OSError:
            time.sleep(0.5)
    return None


def test_make_lab_serves_the_learners_copies_of_the_notebooks(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}  # a headless machine
    env["CV3D_WORKSPACE"] = str(tmp_path / "work")     # the learner's copies, never the tracked notebooks/
    for attempt in range(3):           # other test workers open ports too
        port, token = _free_port(), secrets.token_hex(8)
        proc = _lab(port, token, env)
        try:
            listing = _listing(proc, port, token)
            if listing is None and proc.poll() is not None and attempt < 2:
                continue
            if listing is None:
                proc.kill()
                raise AssertionError("JupyterLab did not answer:\n" + proc.stdout.read()[-3000:])
            names = {item["name"] for item in listing["content"]}
            assert {c.notebook.split("/")[1] for c in READY} <= names, names
            assert "Your notebooks: " + str(tmp_path / "work") in _first_lines(proc)
            return
        finally:
            try:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait(timeout=20)
            except (ProcessLookupError, subprocess.TimeoutExpired):
                try:
                    os.killpg(proc.pid, signal.SIGKILL)
                except ProcessLookupError:
                    pass
                proc.wait()


def _first_lines(proc: subprocess.Popen, n: int = 40) -> str:
    """What `make lab` printed before JupyterLab's own log (read without blocking on a live process)."""
    os.set_blocking(proc.stdout.fileno(), False)
    return "".join(proc.stdout.readlines()[:n])


def test_a_learners_copy_is_never_replaced(tmp_path):
    from graders.study.lab import fill_workspace
    src = tmp_path / "src"
    src.mkdir()
    (src / "01_a.ipynb").write_text("course v1")
    work = tmp_path / "work"
    assert fill_workspace(work, src) == ["01_a.ipynb"]
    (work / "01_a.ipynb").write_text("my answers")
    (src / "01_a.ipynb").write_text("course v2")        # a git pull changes the original
    (src / "02_b.ipynb").write_text("a new chapter")
    assert fill_workspace(work, src) == ["02_b.ipynb"]
    assert (work / "01_a.ipynb").read_text() == "my answers"
