"""graders.kit.datasets: the manifest matches the real files, a missing dataset explains itself, and
fetch checks sha256 (tested offline with file:// URLs)."""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path

import numpy as np
import pytest

from graders.kit import datasets

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def shared() -> Path:
    """The real data folder, from $COURSE_DATA (CI sets it to /work/shared/data)."""
    value = os.environ.get("COURSE_DATA")
    if not value:
        pytest.skip("COURSE_DATA is not set: run with COURSE_DATA=/path/to/data to check the real datasets")
    if not Path(value).is_dir():
        pytest.skip(f"COURSE_DATA={value} does not exist")
    return Path(value)


@pytest.fixture
def empty_env(tmp_path, monkeypatch) -> Path:
    """COURSE_DATA and the cache both point at empty temporary folders."""
    (tmp_path / "course_data").mkdir()
    (tmp_path / "xdg").mkdir()
    monkeypatch.setenv("COURSE_DATA", str(tmp_path / "course_data"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    return tmp_path


# ============================================================ the manifest ====

def test_manifest_is_complete_and_well_formed():
    m = datasets.load_manifest()
    assert list(m["datasets"]) == ["chessboard", "homography", "bal", "posegraph", "trajectories", "flow",
                                   "sacre_coeur", "sceaux_castle"]
    for name, e in m["datasets"].items():
        for key in ("folder", "description", "origin", "terms", "reference"):
            assert e[key], (name, key)
        assert e["files"] and e["bytes"] == sum(f["bytes"] for f in e["files"])
        for f in e["files"]:
            assert f["path"].startswith(e["folder"] + "/")
            assert len(f["sha256"]) == 64 and int(f["sha256"], 16) >= 0
            assert f["url"] == datasets.URL_TEMPLATE.format(repo=f["repo"], commit=f["commit"], path=f["source_path"])
    assert m["bytes"] == sum(e["bytes"] for e in m["datasets"].values())
    # the data themselves never enter the repository
    assert {p.name for p in (REPO / "data").iterdir()} <= {"manifest.json", "README.md"}


def test_manifest_sizes_and_hashes_match_the_real_files(shared):
    listed = set()
    for name in datasets.names():
        assert datasets.verify(name, root=shared) == [], name
        listed |= {f["path"] for f in datasets.info(name)["files"]}
    on_disk = {p.relative_to(shared).as_posix() for p in shared.rglob("*") if p.is_file()}
    assert on_disk - {"README.md", "SOURCES.tsv"} == listed


def test_manifest_origins_match_sources_tsv(shared):
    rows = dict(line.split("\t") for line in (shared / "SOURCES.tsv").read_text().splitlines()[1:] if line)
    full = datasets.load_manifest()["full_commits"]
    for name in datasets.names():
        for f in datasets.info(name)["files"]:
            repo, rest = rows[f["path"]].split("@", 1)
            commit, source_path = rest.split(":", 1)
            assert (f["repo"], f["source_path"]) == (repo, source_path)
            assert f["commit"] == full.get(f"{repo}@{commit}", commit)


# ============================================================ finding files ====

def test_path_finds_files_in_course_data(shared, monkeypatch, tmp_path):
    monkeypatch.setenv("COURSE_DATA", str(shared))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert datasets.data_root() == shared
    assert datasets.path("homography", "graf1.png") == shared / "homography" / "graf1.png"
    assert datasets.path("homography", "homography/graf1.png") == shared / "homography" / "graf1.png"
    assert datasets.path("sacre_coeur") == shared / "sfm" / "sacre_coeur"
    assert all(datasets.available(n) for n in datasets.names())
    with pytest.raises(KeyError, match="graf2.png"):
        datasets.path("homography", "graf2.png")
    with pytest.raises(KeyError, match="unknown dataset"):
        datasets.path("kitti")


def test_missing_dataset_says_how_to_get_it(empty_env):
    with pytest.raises(datasets.DatasetMissing) as err:
        datasets.path("homography", "graf1.png")
    assert isinstance(err.value, FileNotFoundError)
    msg = str(err.value)
    for needed in ("'homography'", "homography/graf1.png", "make fetch-data",
                   "python -m graders.datasets fetch homography", "COURSE_DATA", str(empty_env / "xdg")):
        assert needed in msg, needed
    assert not datasets.available("homography")
    with pytest.raises(datasets.DatasetMissing, match="fetch sacre_coeur"):
        datasets.path("sacre_coeur")
    assert datasets.data_root() == empty_env / "course_data"


def test_announce_says_in_one_line_what_a_notebook_falls_back_to(empty_env, capsys):
    assert datasets.announce("flow", "the five FlyingChairs pairs", "a synthetic pair") is False
    line = capsys.readouterr().out
    assert line.count("\n") == 1
    for needed in ("FlyingChairs", "not found", "a synthetic pair", "python -m graders.datasets fetch flow", "make fetch-data"):
        assert needed in line, needed


def test_announce_names_the_folder_when_found(shared, monkeypatch, capsys):
    monkeypatch.setenv("COURSE_DATA", str(shared))
    assert datasets.announce("flow", "the five FlyingChairs pairs", "a synthetic pair") is True
    line = capsys.readouterr().out
    assert line.count("\n") == 1 and str(shared / "flow") in line and "synthetic" not in line


def test_data_root_falls_back_to_the_cache(empty_env, monkeypatch):
    monkeypatch.delenv("COURSE_DATA")
    assert datasets.data_root() is None  # the cache folder does not exist yet
    (empty_env / "xdg" / "cv3d-course").mkdir()
    assert datasets.data_root() == empty_env / "xdg" / "cv3d-course"
    with pytest.raises(datasets.DatasetMissing, match=r"\(not set\)"):
        datasets.path("bal", "problem-49-7776-pre.txt")


# ============================================================ fetch ====

def _toy_manifest(tmp_path: Path, monkeypatch) -> Path:
    """A one-dataset manifest whose files sit in tmp_path/src and whose URLs are file:// URLs."""
    src = tmp_path / "src"
    (src / "toy" / "sub").mkdir(parents=True)
    contents = {"toy/a.txt": b"hello\n", "toy/sub/b.bin": bytes(range(256)) * 40}
    files = []
    for rel, data in contents.items():
        (src / rel).write_bytes(data)
        files.append({"path": rel, "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest(),
                      "url": (src / rel).as_uri()})
    manifest = {"datasets": {"toy": {"folder": "toy", "files": files, "bytes": sum(f["bytes"] for f in files)}}}
    (tmp_path / "manifest.json").write_text(json.dumps(manifest))
    monkeypatch.setattr(datasets, "MANIFEST_PATH", tmp_path / "manifest.json")
    return src


def test_fetch_downloads_into_the_cache_and_checks_sha256(empty_env, monkeypatch):
    src = _toy_manifest(empty_env, monkeypatch)
    cache = empty_env / "xdg" / "cv3d-course"
    assert not datasets.available("toy")
    assert datasets.fetch("toy") == cache / "toy"  # from each file's own file:// URL
    assert (cache / "toy" / "sub" / "b.bin").read_bytes() == (src / "toy" / "sub" / "b.bin").read_bytes()
    assert datasets.verify("toy") == [] and datasets.available("toy")
    assert datasets.path("toy", "sub/b.bin") == cache / "toy" / "sub" / "b.bin"

    # a corrupted source is refused and leaves nothing behind
    (cache / "toy" / "sub" / "b.bin").unlink()
    (src / "toy" / "sub" / "b.bin").write_bytes(b"\x00" * 10240)
    with pytest.raises(datasets.ChecksumError, match="sha256"):
        datasets.fetch("toy")
    assert sorted(p.name for p in (cache / "toy" / "sub").iterdir()) == []
    assert not datasets.available("toy")


def test_fetch_from_a_mirror_and_verify_spots_corruption(empty_env, monkeypatch):
    src = _toy_manifest(empty_env, monkeypatch)
    dest = empty_env / "elsewhere"
    datasets.fetch("toy", dest=dest, base_url=src.as_uri())
    assert datasets.verify("toy", root=dest) == []
    (dest / "toy" / "a.txt").write_bytes(b"HELLO\n")
    problems = datasets.verify("toy", root=dest)
    assert len(problems) == 1 and "a.txt" in problems[0] and "sha256" in problems[0]
    datasets.fetch("toy", dest=dest, base_url=src.as_uri())  # repairs the changed file
    assert datasets.verify("toy", root=dest) == []


def test_fetch_a_real_dataset_through_file_urls(shared, tmp_path):
    folder = datasets.fetch("homography", dest=tmp_path, base_url=shared.as_uri())
    assert folder == tmp_path / "homography"
    assert datasets.verify("homography", root=tmp_path) == []


def test_cli(shared, monkeypatch, capsys, tmp_path):
    monkeypatch.setenv("COURSE_DATA", str(shared))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert datasets.main(["list"]) == 0
    out = capsys.readouterr().out
    assert all(name in out for name in datasets.names()) and str(shared) in out
    assert datasets.main(["verify", "homography"]) == 0
    assert "homography: ok" in capsys.readouterr().out
    with pytest.raises(SystemExit):
        datasets.main(["fetch"])  # neither a name nor --all


# ============================================================ loaders ====

def test_loaders(shared, monkeypatch):
    monkeypatch.setenv("COURSE_DATA", str(shared))
    img1, img3, H = datasets.load_homography_pair()
    assert img1.shape == img3.shape == (640, 800) and img1.dtype == np.uint8
    assert H.shape == (3, 3) and H[2, 2] == 1 and H[0, 2] == pytest.approx(225.67123)
    calib = datasets.load_chessboard_intrinsics()
    assert calib["K"][0, 0] == pytest.approx(535.916, abs=1e-3) and calib["K"][1, 2] == pytest.approx(235.571, abs=1e-3)
    assert calib["dist"].shape == (5,) and calib["dist"][0] == pytest.approx(-0.26637, abs=1e-5)
    assert calib["rms"] == pytest.approx(0.3926, abs=1e-4)
    assert calib["image_size"] == (640, 480) and calib["pattern_size"] == (9, 6)
    left = datasets.chessboard_images("left")
    assert len(left) == 13 and left == sorted(left) and all(p.name.startswith("left") for p in left)
    assert len(datasets.chessboard_images("right")) == 13
