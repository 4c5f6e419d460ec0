"""Course releases: the student edition and the Gradescope autograder.

    python -m graders release OUT/ [--chapters 1,2]
    python -m graders gradescope --chapter 4 --out autograder.zip [--secret-file S]

The student edition holds the chosen chapters' notebooks (untouched stubs, no outputs), the `graders`
package with only those chapters, the data manifest, docs, README, environment and Makefile: the two
README commands work in it, and it has no `solutions/` (a test installs it in a fresh venv, runs every
notebook and greps it for reference code). Its CONCEPT/DESIGN questions are sealed (graders.grading.seal):
checked locally against salted hashes, with no answer in its files; graded mode judges them from the
instructor's repository.

The autograder follows Gradescope's contract: `setup.sh` installs the pinned environment; the bundle
carries the datasets its chapter grades on (`course_data/`, checked against data/manifest.json; the
build stops if one is missing unless `--without-data`, and then every results.json shows a failed test
naming it, never a silent drop of its real-data cases);
`run_autograder` grades `/autograder/submission` in instructor mode (graded mode, secret seed, hidden
cases) and writes `/autograder/results/results.json`, valid in every failure mode: written before
grading starts, rewritten atomically after every exercise, and inside a time budget shorter than
the autograder's limit. Nothing is printed into it.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import stat
import sys
import zipfile
from pathlib import Path

from graders.core.chapters import READY, by_number
from graders.grading.seal import seal_questions
from graders.grading.standins import swap_twins

ROOT = Path(__file__).resolve().parents[2]
SHARED = ("__init__.py", "__main__.py", "cli.py", "datasets.py", "layers.py")   # graders/*.py
PACKAGES = ("core", "kit", "grading", "study", "oracles")   # every row of graders.layers but the chapters
HOME_NOTEBOOK = "notebooks/00_start_here.ipynb"
RELEASED = "released.json"     # beside chapters.py in a release: the chapters it holds
# What a learner reads in docs/: the conventions the notebooks and checks use, and how a check judges (graded mode,
# isolation). The contributor's template and the instructor's test-time log stay in the course repository.
STUDENT_DOCS = ("CONVENTIONS.md", "ENGINE.md")


def _ignore(_dir, names):
    return [n for n in names if n in ("__pycache__", ".ipynb_checkpoints") or n.endswith(".pyc")]


def _copy_graders(dest: Path, numbers: list[int]) -> None:
    pkg = dest / "graders"
    pkg.mkdir(parents=True)
    for name in SHARED:
        shutil.copy2(ROOT / "graders" / name, pkg / name)
    for sub in PACKAGES:
        shutil.copytree(ROOT / "graders" / sub, pkg / sub, ignore=_ignore)
    for n in numbers:
        ch = by_number(n)
        shutil.copytree(ROOT / "graders" / ch.prefix, pkg / ch.prefix, ignore=_ignore)
    (pkg / RELEASED).write_text(json.dumps(sorted(numbers)))


def _pyproject() -> str:
    text = (ROOT / "pyproject.toml").read_text()
    text = text.replace('include = ["solutions*", "graders*", "benchmarks*"]', 'include = ["graders*"]')
    return text.replace('testpaths = ["tests", "notebooks"]', 'testpaths = ["notebooks"]')


STUDENT_SECTIONS = ("Two commands", "Chapters", "Checking your work", "Real data")   # the rest is the instructor's
SEALED_NOTE = ("CONCEPT and DESIGN answers are sealed in this edition (no file holds them): a check still tells a "
               "right answer from a wrong one (choices one by one; numbers against a band around the answer, a "
               "little wider than the graded tolerance) and opens the model answer once yours is right. Your grade "
               "comes from the course staff's grader, which judges every answer exactly.")


def student_readme(numbers: list[int]) -> str:
    """The release's README: the course README's learner sections only (no teaching, contributing,
    solutions/, benchmarks or tests/), its chapter table cut to the chapters shipped, `make test` described
    as what it runs here (every notebook)."""
    text = (ROOT / "README.md").read_text(encoding="utf-8")
    head, *sections = text.split("\n## ")
    keep = [head.rstrip() + "\n"]
    shipped = {str(n) for n in numbers}
    for section in sections:
        title, _, body = section.partition("\n")
        if title.strip() not in STUDENT_SECTIONS:
            continue
        lines = []
        for line in body.splitlines():
            cells = [c.strip() for c in line.split("|")]
            if line.startswith("| ") and len(cells) > 2 and cells[1].isdigit() and cells[1] not in shipped:
                continue                      # a chapter row of a chapter not in this edition
            if line.startswith("<!--"):
                continue                      # the instructor repo's generator marker
            lines.append(line.replace("run the whole test suite (pytest + every notebook via nbval)",
                                      "run every notebook of this edition top to bottom (nbval)"))
        if title.strip() == "Checking your work":
            lines += ["", SEALED_NOTE]
        keep.append(f"## {title}\n" + "\n".join(lines).rstrip() + "\n")
    chapters = ", ".join(str(n) for n in sorted(numbers))
    keep.insert(1, f"This edition holds chapter{'s' if len(numbers) > 1 else ''} {chapters}: the notebooks, the "
                   "checks (`graders/`) and the data manifest. Frames, poses and pixels follow "
                   "[docs/CONVENTIONS.md](docs/CONVENTIONS.md).\n")
    return "\n".join(keep)


def student_release(out: str | Path, numbers: list[int] | None = None) -> Path:
    """Write the student edition of `numbers` (default: every ready chapter) into `out` (must not exist)."""
    out = Path(out)
    numbers = sorted(numbers or [c.number for c in READY])
    if out.exists():
        raise FileExistsError(f"{out} exists; give a new folder")
    out.mkdir(parents=True)
    _copy_graders(out, numbers)
    (out / "notebooks").mkdir()
    for n in numbers:
        nb = ROOT / by_number(n).notebook
        shutil.copy2(nb, out / "notebooks" / nb.name)
    if (ROOT / HOME_NOTEBOOK).exists():     # the course home: map, progress, reference tables
        shutil.copy2(ROOT / HOME_NOTEBOOK, out / HOME_NOTEBOOK)
    for name in ("environment.txt", "Makefile", "conftest.py", ".gitignore"):
        shutil.copy2(ROOT / name, out / name)
    (out / "README.md").write_text(student_readme(numbers), encoding="utf-8")
    shutil.copytree(ROOT / "data", out / "data", ignore=_ignore)
    (out / "docs").mkdir()
    for name in STUDENT_DOCS:
        shutil.copy2(ROOT / "docs" / name, out / "docs" / name)
    (out / "pyproject.toml").write_text(_pyproject())
    swap_twins(out)                   # stand-ins that are a solution -> their library twin (graders.grading.standins)
    seal_questions(out, numbers)      # last: it reads which names the release's other files and notebooks use
    return out


# ------------------------------------------------------------------ Gradescope

SETUP_SH = """#!/usr/bin/env bash
# Gradescope runs this once, as root, when the autograder image is built.
set -euo pipefail
cd /autograder/source
apt-get update -qq && apt-get install -y -qq python3.11 python3.11-venv > /dev/null || true
PY=$(command -v python3.11 || command -v python3)
$PY -m venv /autograder/venv
/autograder/venv/bin/python -m pip install -q torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu
/autograder/venv/bin/python -m pip install -q -r environment.txt
/autograder/venv/bin/python -m pip install -q --no-deps -e .   # editable, as make install: data/ stays beside graders/
"""

RUN_AUTOGRADER = """#!/usr/bin/env bash
# Gradescope runs this for every submission. All output goes to a log, never into results.json.
ROOT="${AUTOGRADER_ROOT:-/autograder}"
PY="${AUTOGRADER_PYTHON:-$ROOT/venv/bin/python}"
cd "$ROOT/source"
exec "$PY" -m graders gradescope-run --root "$ROOT" >> "$ROOT/results/autograder.log" 2>&1
"""


BUNDLE_DATA = "course_data"    # in the autograder's source folder: the datasets its chapter grades on


def chapter_datasets(number: int) -> list[str]:
    """The datasets a chapter's grader reads: each manifest name that its grader package spells as a
    string literal (`datasets.available("chessboard")`, PHOTO_SETS' keys)."""
    import ast
    from graders.kit import datasets
    known, found = set(datasets.names()), set()
    for py in sorted((ROOT / "graders" / by_number(number).prefix).rglob("*.py")):
        for node in ast.walk(ast.parse(py.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and node.value in known:
                found.add(node.value)
    return sorted(found)


def _copy_datasets(dest: Path, names: list[str], allow_missing: bool) -> list[str]:
    """Copy each dataset's manifest files, checked against their sha256, into dest; returns the names
    copied. A dataset that is missing or corrupt stops the build unless allow_missing (then the autograder
    reports it as a failed test on every submission)."""
    from graders.kit import datasets
    copied = []
    for name in names:
        root = datasets.where(name)
        problems = datasets.verify(name, root) if root is not None else [f"{name}: not in $COURSE_DATA or the cache"]
        if problems:
            if allow_missing:
                continue
            raise datasets.DatasetMissing(f"chapter's autograder grades on the dataset {name!r}, which is not usable "
                                          f"here ({problems[0]}). Run `make fetch-data` or set COURSE_DATA, or "
                                          f"build with --without-data (its real-data cases then fail visibly).")
        for f in datasets.info(name)["files"]:
            (dest / f["path"]).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(root / f["path"], dest / f["path"])
        copied.append(name)
    return copied


def gradescope_bundle(out_zip: str | Path, number: int, secret: bytes | None = None,
                      time_budget: float | None = None, allow_missing_data: bool = False) -> Path:
    """The autograder zip for one chapter: setup.sh, run_autograder, the graders, the pins, the secret,
    and the datasets the chapter grades on (course_data/, the layout of $COURSE_DATA)."""
    import tempfile
    out_zip = Path(out_zip)
    with tempfile.TemporaryDirectory(prefix="cv3d-bundle-") as tmp:
        src = Path(tmp)
        _copy_graders(src, [number])
        for name in ("environment.txt",):
            shutil.copy2(ROOT / name, src / name)
        shutil.copytree(ROOT / "data", src / "data", ignore=_ignore)
        (src / "pyproject.toml").write_text(_pyproject())
        needed = chapter_datasets(number)
        (src / BUNDLE_DATA).mkdir()
        _copy_datasets(src / BUNDLE_DATA, needed, allow_missing_data)
        config = {"chapter": number, "datasets": needed}
        if time_budget:
            config["time_budget"] = time_budget
        (src / "autograder.json").write_text(json.dumps(config))
        if secret:
            (src / "secret").write_bytes(secret)
        (src / "setup.sh").write_text(SETUP_SH)
        (src / "run_autograder").write_text(RUN_AUTOGRADER)
        with zipfile.ZipFile(out_zip, "w", zipfile.ZIP_DEFLATED) as z:
            for path in sorted(src.rglob("*")):
                if path.is_file():
                    info = zipfile.ZipInfo(str(path.relative_to(src)))
                    mode = 0o755 if path.name in ("setup.sh", "run_autograder") else 0o644
                    info.external_attr = (stat.S_IFREG | mode) << 16
                    info.compress_type = zipfile.ZIP_DEFLATED
                    z.writestr(info, path.read_bytes())
    return out_zip


def _submission_file(folder: Path, number: int) -> Path | None:
    files = sorted(p for p in folder.rglob("*") if p.is_file() and p.suffix in (".ipynb", ".py"))
    stem = by_number(number).notebook.split("/")[1]
    named = [p for p in files if p.name == stem]
    notebooks = [p for p in files if p.suffix == ".ipynb"]
    return (named or notebooks or files or [None])[0]


def _data_failures(source: Path, config: dict) -> list:
    """A failed, visible, 0-point test for each dataset the chapter grades on that the bundle lacks (or holds
    corrupt): its real-data cases cannot run, and the learner and the staff see that they did not."""
    from graders.kit import datasets
    from graders.core.report import CaseResult, ExerciseResult
    failures = []
    for name in config.get("datasets", []):
        problems = datasets.verify(name, source / BUNDLE_DATA)
        if problems:
            msg = (f"the autograder lacks the dataset {name!r} ({problems[0]}): this chapter's real-data cases on it "
                   f"were not run. This is the course staff's problem, not yours: please tell them.")
            failures.append(ExerciseResult(id="data", title=f"real data: {name}", name=name, kind="data", max_score=0.0,
                                           seed=0, status="failed", message=msg, replayable=False,
                                           cases=[CaseResult(name=f"dataset {name}", message="missing")]))
    return failures


def gradescope_run(root: str | Path) -> int:
    """Grade /autograder/submission into /autograder/results/results.json (see the module docstring)."""
    from graders.grading.runner import TIME_BUDGET, check_file
    from graders.core.report import write_gradescope as _write
    root = Path(root)
    source = root / "source"
    results = root / "results" / "results.json"
    results.parent.mkdir(parents=True, exist_ok=True)
    _write(results, [], "The autograder started but did not finish: please resubmit or tell staff.")
    config = json.loads((source / "autograder.json").read_text())
    if (source / BUNDLE_DATA).is_dir():      # the bundle's datasets, for the grader and its worker processes
        os.environ["COURSE_DATA"] = str(source / BUNDLE_DATA)
    missing = _data_failures(source, config)

    def write_gradescope(path, partial, message=""):
        _write(path, list(partial) + missing, message)
    number = int(config["chapter"])
    secret_file = source / "secret"
    secret = secret_file.read_bytes().strip() if secret_file.exists() else None
    sub = _submission_file(root / "submission", number)
    if sub is None:
        write_gradescope(results, [], "No notebook (.ipynb) or module (.py) found in your submission.")
        return 0
    meta = root / "submission_metadata.json"
    sid = sub.stem
    if meta.exists():
        try:
            sid = str(json.loads(meta.read_text()).get("id", sid))
        except ValueError:
            pass
    from graders.core.engine import chapter
    ids = [ex.id for ex in chapter(by_number(number).key)]

    def save(partial):
        write_gradescope(results, partial, "grading in progress")
    try:
        graded, message = check_file(sub, only=ids, time_budget=float(config.get("time_budget", TIME_BUDGET)),
                                     graded=True, on_result=save, secret=secret, submission=sid)
        write_gradescope(results, graded, message)
    except Exception as exc:       # a grader bug must still leave a valid file that says so
        write_gradescope(results, [], f"The autograder failed ({type(exc).__name__}: {exc}); please tell staff.")
    return 0


def main(argv: list[str]) -> int:
    command, rest = argv[0], argv[1:]
    ap = argparse.ArgumentParser(prog=f"python -m graders {command}")
    if command == "release":
        ap.add_argument("out")
        ap.add_argument("--chapters", help="comma-separated chapter numbers (default: all ready)")
        args = ap.parse_args(rest)
        out = student_release(args.out, [int(c) for c in args.chapters.split(",")] if args.chapters else None)
        print(f"student edition in {out}")
    elif command == "gradescope":
        ap.add_argument("--chapter", required=True, type=int)
        ap.add_argument("--out", required=True)
        ap.add_argument("--secret-file")
        ap.add_argument("--time-budget", type=float, help="seconds (default: the shell grader's 540)")
        ap.add_argument("--without-data", action="store_true",
                        help="build even if a dataset the chapter grades on is missing (its cases then fail visibly)")
        args = ap.parse_args(rest)
        secret = Path(args.secret_file).read_bytes().strip() if args.secret_file else None
        zip_path = gradescope_bundle(args.out, args.chapter, secret, args.time_budget, args.without_data)
        print(f"autograder in {zip_path}")
    else:
        ap.add_argument("--root", default=os.environ.get("AUTOGRADER_ROOT", "/autograder"))
        return gradescope_run(ap.parse_args(rest).root)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
