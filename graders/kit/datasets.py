"""Real datasets by name: where they are, how to get them, and small typed loaders.

The data are other people's files, so the repository holds only data/manifest.json: per dataset a
description, the public origin and terms, and per file its path, size and sha256. Files are found
under `$COURSE_DATA` (CI points it at a shared folder), then in the user cache
(`$XDG_CACHE_HOME/cv3d-course`, default `~/.cache/cv3d-course`), which `fetch` fills:

    python -m graders.datasets list
    python -m graders.datasets fetch homography      # or: fetch --all  (= make fetch-data)
    python -m graders.datasets verify homography

Both folders share one layout: a file's manifest `path` (e.g. 'homography/graf1.png') is relative
to the folder.
"""
from __future__ import annotations

import argparse
import csv
import hashlib
import json
import os
import sys
import tempfile
import urllib.request
from pathlib import Path
from typing import Any, Iterable

import numpy as np

MANIFEST_PATH = Path(__file__).resolve().parents[2] / "data" / "manifest.json"
CACHE_NAME = "cv3d-course"
URL_TEMPLATE = "https://raw.githubusercontent.com/{repo}/{commit}/{path}"


class DatasetMissing(FileNotFoundError):
    """A dataset (or one of its files) is in neither $COURSE_DATA nor the cache."""


class ChecksumError(ValueError):
    """A downloaded file's sha256 differs from the manifest's."""


# ============================================================ manifest and folders ====

def load_manifest() -> dict[str, Any]:
    """The parsed data/manifest.json (read on every call: it is small, and tests swap it)."""
    return json.loads(Path(MANIFEST_PATH).read_text())


def names() -> list[str]:
    """Dataset names in manifest order."""
    return list(load_manifest()["datasets"])


def info(dataset: str) -> dict[str, Any]:
    """The manifest entry of one dataset; KeyError lists the valid names."""
    datasets = load_manifest()["datasets"]
    if dataset not in datasets:
        raise KeyError(f"unknown dataset {dataset!r}; the manifest lists {list(datasets)}")
    return datasets[dataset]


def cache_dir() -> Path:
    """The download cache: $XDG_CACHE_HOME/cv3d-course, else ~/.cache/cv3d-course (may not exist)."""
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / CACHE_NAME


def _course_data() -> Path | None:
    value = os.environ.get("COURSE_DATA")
    return Path(value).expanduser() if value else None


def roots() -> list[Path]:
    """Folders searched, in order: $COURSE_DATA (if set and present), then the cache (if present)."""
    return [p for p in (_course_data(), cache_dir()) if p is not None and p.is_dir()]


def data_root() -> Path | None:
    """$COURSE_DATA if set and present, else the cache folder if present, else None."""
    found = roots()
    return found[0] if found else None


def _missing_message(dataset: str, what: str) -> str:
    cd = _course_data()
    where = (f"$COURSE_DATA={cd}" + ("" if cd.is_dir() else " (no such folder)")) if cd else "$COURSE_DATA (not set)"
    return (f"Dataset {dataset!r} is not available: {what} is in neither {where} nor the cache {cache_dir()}. "
            f"Get it with `make fetch-data` (all datasets) or `python -m graders.datasets fetch {dataset}`, "
            f"or set COURSE_DATA to a folder that contains {what}.")


def path(dataset: str, file: str | None = None) -> Path:
    """Local path of a dataset's folder (file=None) or of one of its files ('graf1.png' or
    'homography/graf1.png'). Looks in $COURSE_DATA, then the cache; a folder counts only if it
    holds every file of the manifest. Raises DatasetMissing saying how to get it."""
    entry = info(dataset)
    folder = entry["folder"]
    if file is None:
        root = where(dataset)
        if root is None:
            raise DatasetMissing(_missing_message(dataset, f"{folder}/ (all {len(entry['files'])} files)"))
        return root / folder
    rel = file if file.startswith(folder + "/") else f"{folder}/{file}"
    known = [f["path"] for f in entry["files"]]
    if rel not in known:
        raise KeyError(f"dataset {dataset!r} has no file {file!r}; it has {[k[len(folder) + 1:] for k in known]}")
    for root in roots():
        if (root / rel).is_file():
            return root / rel
    raise DatasetMissing(_missing_message(dataset, rel))


def where(dataset: str) -> Path | None:
    """The first of $COURSE_DATA / cache that holds every file of `dataset`, else None."""
    wanted = [f["path"] for f in info(dataset)["files"]]
    return next((root for root in roots() if all((root / p).is_file() for p in wanted)), None)


def available(dataset: str) -> bool:
    """True if every file of `dataset` is present in $COURSE_DATA or in the cache."""
    return where(dataset) is not None


def announce(dataset: str, real: str, stand_in: str) -> bool:
    """Print one line a notebook's reader sees: which data its demos and checks use. `real` names the
    real set, `stand_in` what replaces it when the set is missing (then the line gives the fetch command).
    Returns available(dataset)."""
    root = where(dataset)
    if root is not None:
        print(f"Data: {real} ({root / info(dataset)['folder']}).")
    else:
        print(f"Data: {real} not found, so this notebook uses {stand_in}. For the real set: "
              f"`{fetch_command(dataset)}` (or `make fetch-data` for all), then restart the kernel.")
    return root is not None


def fetch_command(dataset: str) -> str:
    """The shell command that puts `dataset` in the cache (what every "not found" line tells the learner)."""
    return f"python -m graders.datasets fetch {dataset}"


def missing_note(wanted: Iterable[str]) -> str:
    """One line for a result judged without real data: which of the datasets `wanted` are missing and the
    command that fetches each; '' when all are present (an exercise's real-data cases are then drawn)."""
    missing = [d for d in wanted if not available(d)]
    if not missing:
        return ""
    commands = " and ".join(f"`{fetch_command(d)}`" for d in missing)
    return (f"its real-data cases were not run: {', '.join(repr(d) for d in missing)} not found "
            f"({commands}, then restart the kernel)")


def sha256(file: Path) -> str:
    """Hex sha256 of a file, read in 1 MiB blocks."""
    h = hashlib.sha256()
    with open(file, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def verify(dataset: str, root: Path | None = None) -> list[str]:
    """Problems with a dataset's local copy (empty list: all files present with the manifest's
    size and sha256). root: folder to check; default the first of $COURSE_DATA / cache holding
    the dataset's folder."""
    entry = info(dataset)
    if root is None:
        root = next((r for r in roots() if (r / entry["folder"]).is_dir()), None)
        if root is None:
            return [_missing_message(dataset, entry["folder"] + "/")]
    problems = []
    for f in entry["files"]:
        p = Path(root) / f["path"]
        if not p.is_file():
            problems.append(f"{p}: missing")
        elif p.stat().st_size != f["bytes"]:
            problems.append(f"{p}: {p.stat().st_size} bytes, manifest says {f['bytes']}")
        elif sha256(p) != f["sha256"]:
            problems.append(f"{p}: sha256 differs from the manifest (file changed or corrupt)")
    return problems


# ============================================================ download ====

def file_url(f: dict[str, Any], base_url: str | None = None) -> str:
    """Where to download one manifest file: `base_url`/<path> for a mirror laid out like
    $COURSE_DATA (http(s):// or file://), else its public origin."""
    if base_url:
        return base_url.rstrip("/") + "/" + f["path"]
    return f.get("url") or URL_TEMPLATE.format(repo=f["repo"], commit=f["commit"], path=f["source_path"])


def _download(url: str, target: Path, expected_sha256: str | None) -> None:
    """Stream `url` to a temporary file next to `target`, check its sha256, then move it in place,
    so an interrupted or corrupt download never leaves a file that looks complete."""
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=target.parent, prefix=target.name + ".", suffix=".part")
    try:
        h = hashlib.sha256()
        with os.fdopen(fd, "wb") as out, urllib.request.urlopen(url, timeout=60) as response:
            for block in iter(lambda: response.read(1 << 20), b""):
                h.update(block)
                out.write(block)
        if expected_sha256 is not None and h.hexdigest() != expected_sha256:
            raise ChecksumError(f"{url}: sha256 {h.hexdigest()} differs from the manifest's {expected_sha256}; "
                                f"not saved (the source changed, or the download was corrupted)")
        os.replace(tmp, target)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def fetch(name: str, dest: Path | str | None = None, verify: bool = True, base_url: str | None = None,
          quiet: bool = True) -> Path:
    """Download dataset `name` into `dest` (default: the cache) and return its folder there.

    Files already present with the right sha256 are kept. base_url (default $COURSE_DATA_URL):
    a mirror laid out like $COURSE_DATA instead of the public origins. With verify=True a file
    whose sha256 differs from the manifest raises ChecksumError and is not saved.
    """
    entry = info(name)
    dest = Path(dest) if dest is not None else cache_dir()
    base_url = base_url or os.environ.get("COURSE_DATA_URL")
    for f in entry["files"]:
        target = dest / f["path"]
        if target.is_file() and target.stat().st_size == f["bytes"] and (not verify or sha256(target) == f["sha256"]):
            continue
        url = file_url(f, base_url)
        if not quiet:
            print(f"  {f['path']}  ({f['bytes'] / 1e6:.2f} MB)  <- {url}", flush=True)
        _download(url, target, f["sha256"] if verify else None)
    return dest / entry["folder"]


# ============================================================ loaders ====

def load_homography_pair(gray: bool = True) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Oxford 'graf' images 1 and 3 and their true homography.

    Returns (img1, img3: (640, 800) uint8, or (640, 800, 3) BGR if gray=False; H: (3, 3) float64,
    x3 ~ H x1 in pixels, as distributed in H1to3p.xml).
    """
    import cv2
    flag = cv2.IMREAD_GRAYSCALE if gray else cv2.IMREAD_COLOR
    img1 = cv2.imread(str(path("homography", "graf1.png")), flag)
    img3 = cv2.imread(str(path("homography", "graf3.png")), flag)
    fs = cv2.FileStorage(str(path("homography", "H1to3p.xml")), cv2.FILE_STORAGE_READ)
    H = np.asarray(fs.getNode("H13").mat(), float)
    fs.release()
    return img1, img3, H


def load_chessboard_intrinsics() -> dict[str, Any]:
    """OpenCV's calibration of the 13 left chessboard views (left_intrinsics.yml).

    Returns dict(K: (3, 3), dist: (5,), rms: float (mean reprojection error, px),
    image_size: (w, h), pattern_size: (cols, rows) inner corners, square: float metres).
    """
    import cv2
    fs = cv2.FileStorage(str(path("chessboard", "left_intrinsics.yml")), cv2.FILE_STORAGE_READ)
    try:
        return {
            "K": np.asarray(fs.getNode("camera_matrix").mat(), float),
            "dist": np.asarray(fs.getNode("distortion_coefficients").mat(), float).ravel(),
            "rms": float(fs.getNode("avg_reprojection_error").real()),
            "image_size": (int(fs.getNode("image_width").real()), int(fs.getNode("image_height").real())),
            "pattern_size": (int(fs.getNode("board_width").real()), int(fs.getNode("board_height").real())),
            "square": float(fs.getNode("square_size").real()),
        }
    finally:
        fs.release()


def chessboard_images(side: str = "left") -> list[Path]:
    """Sorted paths of the 13 chessboard views of one camera ('left' or 'right')."""
    if side not in ("left", "right"):
        raise ValueError(f"side must be 'left' or 'right', got {side!r}")
    files = [f["path"].split("/")[-1] for f in info("chessboard")["files"]]
    return [path("chessboard", f) for f in sorted(files) if f.startswith(side) and f.endswith(".jpg")]


# ============================================================ maintainers ====

def refresh_manifest(source: Path | str, manifest: dict[str, Any] | None = None) -> dict[str, Any]:
    """Recompute every dataset's file list, sizes and sha256 from a local copy of the data.

    source: a folder laid out like $COURSE_DATA with a SOURCES.tsv (`file<TAB>owner/repo@commit:path`).
    Descriptions and terms are kept; files are all those under each dataset's folder.
    """
    source = Path(source)
    manifest = manifest if manifest is not None else load_manifest()
    with open(source / "SOURCES.tsv", newline="") as f:
        origin = {row["file"]: row["from"] for row in csv.DictReader(f, delimiter="\t")}
    for entry in manifest["datasets"].values():
        files = []
        for p in sorted((source / entry["folder"]).rglob("*")):
            if not p.is_file():
                continue
            rel = p.relative_to(source).as_posix()
            repo, rest = origin[rel].split("@", 1)
            commit, source_path = rest.split(":", 1)
            # SOURCES.tsv abbreviates commits; use the full SHA wherever a maintainer recorded it.
            commit = manifest.get("full_commits", {}).get(f"{repo}@{commit}", commit)
            files.append({"path": rel, "bytes": p.stat().st_size, "sha256": sha256(p), "repo": repo,
                          "commit": commit, "source_path": source_path,
                          "url": URL_TEMPLATE.format(repo=repo, commit=commit, path=source_path)})
        entry["files"] = files
        entry["bytes"] = sum(f["bytes"] for f in files)
    manifest["bytes"] = sum(e["bytes"] for e in manifest["datasets"].values())
    return manifest


def _fetch_and_say(name: str, dest: str | None, base_url: str | None) -> bool:
    """Fetch one dataset for the command line: one line of progress per file, one line (no traceback) if it
    fails; folders the failed fetch created and left empty are removed."""
    print(f"{name}: fetching {info(name)['bytes'] / 1e6:.2f} MB", flush=True)
    try:
        print(f"{name}: ready in {fetch(name, dest, base_url=base_url, quiet=False)}")
        return True
    except (OSError, ChecksumError) as exc:     # urllib's URLError is an OSError
        print(f"{name}: FAILED: {getattr(exc, 'reason', None) or exc}", file=sys.stderr)
        folder = (Path(dest) if dest is not None else cache_dir()) / info(name)["folder"]
        for d in sorted((p for p in [folder, *folder.rglob("*")] if p.is_dir()), key=lambda p: -len(p.parts)):
            if not any(d.iterdir()):
                d.rmdir()
        return False


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m graders.datasets", description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="datasets, sizes, and where each is found")
    p_fetch = sub.add_parser("fetch", help="download into the cache and check sha256")
    p_fetch.add_argument("name", nargs="?")
    p_fetch.add_argument("--all", action="store_true", help="every dataset in the manifest")
    p_fetch.add_argument("--dest", help="folder to fill instead of the cache")
    p_fetch.add_argument("--base-url", help="a mirror laid out like $COURSE_DATA (default: public origins)")
    p_verify = sub.add_parser("verify", help="check sizes and sha256 of a local copy")
    p_verify.add_argument("name", nargs="?")
    p_verify.add_argument("--all", action="store_true")
    p_refresh = sub.add_parser("refresh-manifest", help="(maintainers) rehash a local copy into data/manifest.json")
    p_refresh.add_argument("source")
    args = parser.parse_args(argv)

    if args.command == "list":
        for name in names():
            e = info(name)
            print(f"{name:14s} {e['bytes'] / 1e6:6.2f} MB  {len(e['files']):3d} files  {where(name) or 'missing'}")
        print(f"search order: $COURSE_DATA ({_course_data() or 'not set'}), then the cache {cache_dir()}")
        return 0
    if args.command == "refresh-manifest":
        MANIFEST_PATH.write_text(json.dumps(refresh_manifest(args.source), indent=1) + "\n")
        print(f"wrote {MANIFEST_PATH}")
        return 0
    if not args.all and not args.name:
        parser.error(f"{args.command}: give a dataset name ({', '.join(names())}) or --all")
    chosen = names() if args.all else [args.name]
    if args.name and args.name not in names():
        parser.error(f"unknown dataset {args.name!r}; choose from {', '.join(names())}")
    if args.command == "fetch":
        failed = [name for name in chosen if not _fetch_and_say(name, args.dest, args.base_url)]
        if failed:
            print(f"not fetched: {', '.join(failed)}. Offline? Point $COURSE_DATA at a folder that holds the data "
                  "(a copy of another machine's), or fetch from a mirror laid out like it: --base-url URL or "
                  "$COURSE_DATA_URL. The notebooks run without the data, on synthetic stand-ins.", file=sys.stderr)
        return 1 if failed else 0
    bad = 0
    for name in chosen:
        problems = verify(name)
        bad += bool(problems)
        print(f"{name}: " + ("ok" if not problems else "\n  ".join(["PROBLEMS"] + problems)))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
