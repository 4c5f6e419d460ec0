"""graders.kit.diskcache: values survive the trip to disk exactly, an entry is found only while its inputs, code and
libraries are unchanged; graded mode's judge reads only an entry its learners' user cannot have written, or none."""
from __future__ import annotations

import os
import subprocess
import sys
import types
from pathlib import Path

import numpy as np

from graders.kit import diskcache

ROOT = Path(__file__).resolve().parents[2]


def test_values_come_back_exactly():
    value = {"keypoints": [np.random.default_rng(0).normal(size=(5, 2)), np.zeros((0, 2))],
             "matches": {(0, 1): np.arange(6, dtype=np.int64).reshape(3, 2)}, "sizes": [(640, 480)],
             "cameras": {3: {"f": np.float64(1 / 3), "k1": 0.1, "R": np.eye(3, dtype=np.float32)}}, "K": None}
    back = diskcache.decode(diskcache.encode(value))
    assert back["matches"].keys() == {(0, 1)} and back["sizes"] == [(640, 480)] and back["K"] is None
    assert back["cameras"][3]["f"] == 1 / 3 and back["cameras"][3]["R"].dtype == np.float32
    for a, b in zip(value["keypoints"], back["keypoints"]):
        assert a.shape == b.shape and np.array_equal(a, b)


def _counted(tmp_path: Path, monkeypatch):
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    data = tmp_path / "input.txt"
    data.write_text("1 2 3")
    calls = []
    module = types.SimpleNamespace(__file__=__file__)

    @diskcache.on_disk(lambda scale: [data], code=[module], libraries=["numpy"])
    def oracle(scale):
        calls.append(scale)
        return {"x": scale * np.loadtxt(data)}
    return oracle, data, calls


def test_an_entry_is_used_until_its_input_changes(tmp_path, monkeypatch):
    oracle, data, calls = _counted(tmp_path, monkeypatch)
    assert np.array_equal(oracle(2)["x"], [2, 4, 6]) and np.array_equal(oracle(2)["x"], [2, 4, 6])
    assert calls == [2]                     # the second call read the disk
    oracle(3)
    assert calls == [2, 3]                  # other arguments, another entry
    data.write_text("1 2 4")
    assert np.array_equal(oracle(2)["x"], [2, 4, 8]) and calls == [2, 3, 2]


def test_a_disabled_cache_neither_reads_nor_writes(tmp_path, monkeypatch):
    oracle, data, calls = _counted(tmp_path, monkeypatch)
    oracle(2)
    entry, = (tmp_path / "cache").rglob("oracle-*.json")
    entry.write_text('{"dict": [["x", {"ndarray": ["<f8", [3], [0, 0, 0]]}]]}')    # a planted answer
    assert np.array_equal(oracle(2)["x"], [0, 0, 0])                                  # self-study reads it
    monkeypatch.setattr(diskcache, "_enabled", True)
    diskcache.disable()
    assert np.array_equal(oracle(2)["x"], [2, 4, 6]) and calls == [2, 2]
    assert len(list((tmp_path / "cache").rglob("*.json"))) == 1


def test_the_judge_only_reads_what_only_its_user_can_have_written(tmp_path, monkeypatch):
    oracle, data, calls = _counted(tmp_path, monkeypatch)
    oracle(2)
    entry, = (tmp_path / "cache").rglob("oracle-*.json")
    entry.write_text('{"dict": [["x", {"ndarray": ["<f8", [3], [0, 0, 0]]}]]}')    # as its user wrote it: read
    monkeypatch.setattr(diskcache, "_judge_only", True)
    assert np.array_equal(oracle(2)["x"], [0, 0, 0]) and calls == [2]
    entry.chmod(0o666)                                       # an entry another user may have written: recomputed
    assert np.array_equal(oracle(2)["x"], [2, 4, 6]) and calls == [2, 2]
    entry.write_text('{"dict": [["x", {"ndarray": ["<f8", [3], [0, 0, 0]]}]]}')
    entry.chmod(0o600)
    entry.parent.chmod(0o777)                                # in a folder others may write: recomputed
    assert np.array_equal(oracle(2)["x"], [2, 4, 6]) and calls == [2, 2, 2]
    entry.parent.chmod(0o755)
    entry.write_text('{"dict": [["x", {"ndarray": ["<f8", [3], [0, 0, 0]]}]]}')
    link = entry.with_name("planted.json")
    entry.rename(link)
    entry.symlink_to(link)                                   # a link, even to this user's file: recomputed
    assert np.array_equal(oracle(2)["x"], [2, 4, 6]) and calls == [2, 2, 2, 2]
    if os.geteuid() == 0:                                    # owned by another user: recomputed
        entry.unlink()
        link.rename(entry)
        os.chown(entry, 54321, 54321)
        assert np.array_equal(oracle(2)["x"], [2, 4, 6]) and calls == [2, 2, 2, 2, 2]


def test_graded_workers_read_it_only_when_their_learners_run_as_another_user(tmp_path):
    # graders.grading.worker: on in self-study; in graded mode judge-only where every learner process runs as another
    # user (namespaces: nobody; process level as root: a uid of its own), else off.
    source = tmp_path / "learner.py"
    source.write_text("x = 1\n")
    code = ("import os, sys; from graders.grading import worker; from graders.kit import diskcache\n"
            "r, w = os.pipe(); worker.main([sys.argv[1], str(w), '--ids', '1.1'] + sys.argv[2:])\n"
            "from graders.grading.isolation import learners_leave_this_user as other\n"
            "print(repr(diskcache.mode()), other())")
    env = dict(os.environ, CV3D_SEED="0")
    runs = [subprocess.run([sys.executable, "-c", code, str(source), *flag], capture_output=True, text=True,
                           cwd=ROOT, env=env, timeout=300) for flag in ([], ["--graded"])]
    last = [r.stdout.splitlines()[-1] if r.stdout else r.stderr[-2000:] for r in runs]
    assert last[0].startswith("'on'"), last
    assert last[1] in ("'judge only' True", "'off' False"), last
