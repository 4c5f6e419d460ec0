"""Graded coursework at class scale: generate submissions, grade them in one batch, compare with what
each should score.

    python -m benchmarks.coursework [--out DIR] [--per-chapter 40] [--workers 2] [--chapters 1,2,3,4,5]

Submissions per chapter: the reference (full marks), mutants (one exercise answered by a catalogued
wrong implementation: that exercise loses points, every other keeps full marks) and hostile code
(endless loops, fork bombs, 30 GB allocations, os._exit, output floods, writes outside the working
folder, reading the secret or `expected`, patching numpy or the grader: zero on what they attack,
and nothing left running or written). Prints the expected-vs-got table per category, throughput
(submissions per minute), and the batch's peak memory. `tests/grading/test_coursework.py` runs a small one.
"""
from __future__ import annotations

import argparse
import csv
import inspect
import json
import os
import random
import resource
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

import nbformat

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

HOSTILE = {   # name -> body of the attacked function (the exercise is the chapter's first CODE exercise)
    "loop": "while True:\n        pass",
    "fork_bomb": "import os\n    while True:\n        os.fork()",
    "allocate_30GB": "import numpy as np\n    return np.ones(int(30e9 / 8))",
    "os_exit": "import os\n    os._exit(0)",
    "flood": "print('x' * 100_000_000)\n    return None",
    "write_outside": "import glob\n    for p in glob.glob(%r + '/graders/*.py'):\n        open(p, 'a').write('# cv3d-escaped-marker')\n"
                     "    open('/tmp/cv3d-escaped', 'w').write('x')\n    return None",
    "read_secret": "import os\n    secret = os.environ.get('CV3D_GRADING_SECRET') or os.environ.get('CV3D_HIDDEN_SEEDS')\n"
                   "    for pid in os.listdir('/proc'):\n        try:\n"
                   "            secret = secret or open('/proc/%s/environ' % pid).read().split('CV3D_HIDDEN_SEEDS=')[1]\n"
                   "        except Exception:\n            pass\n    raise RuntimeError('found: %s' % secret)",
    "stack_walk": "import inspect\n    for f in inspect.stack():\n        c = f.frame.f_locals.get('case')\n"
                  "        if c is not None and hasattr(c, 'expected'):\n            return c.expected\n"
                  "    raise RuntimeError('no expected in reach')",
    "patch_numpy": "import numpy as np\n    np.linalg.norm = lambda *a, **k: 0.0\n    np.max = lambda *a, **k: 0.0\n"
                   "    return np.zeros((len(args[0]), 2))",
    "patch_grader": "import graders.core.engine as e\n    e.grade = lambda *a, **k: None\n"
                    "    e._judge_case = lambda *a, **k: None\n    return None",
}


def _chapters(numbers):
    from graders.core.chapters import by_number
    return [by_number(n) for n in numbers]


def _first_code(ch):
    from graders.core.engine import chapter
    return next(ex for ex in chapter(ch.key) if ex.kind == "code")


def _with_stub(ch, name: str | None = None, source: str = "") -> nbformat.NotebookNode:
    """The solved notebook, with the reference import of `name` (if given) replaced by `source`."""
    from notebook_stubs import solved as _solved
    nb = _solved(ROOT / ch.notebook)
    for cell in nb.cells:
        if name and "stub" in cell.get("metadata", {}).get("tags", []):
            lines = cell.source.split("\n")
            if any(line.endswith(f" import {name}") for line in lines):
                cell.source = "\n".join([ln for ln in lines if not ln.endswith(f" import {name}")] + [source])
    return nb


def _mutant_source(module, fn, name: str) -> str:
    """A learner cell answering `name` with a catalogued mutant: the catalogue file is run as it stands
    (its module-level helpers included, which a notebook's definitions-only extraction would drop). The file is the
    one that defines `fn`: a chapter's catalogue may gather its MUTANTS from several files (ch08_dense_nerf, ...)."""
    path = inspect.getfile(fn) if inspect.isfunction(fn) else inspect.getfile(module)
    return (f"MUTANT_CATALOGUE = __import__('runpy').run_path({path!r})\n\n"
            f"def {name}(*args, **kwargs):\n    return MUTANT_CATALOGUE[{fn.__name__!r}](*args, **kwargs)\n")


def build(out: Path, numbers, per_chapter: int, seed: int = 0) -> dict[str, dict]:
    """Write submissions into out/; returns id -> {chapter, category, attacked exercise or None}."""
    import importlib
    rng = random.Random(seed)
    out.mkdir(parents=True, exist_ok=True)
    plan: dict[str, dict] = {}
    for ch in _chapters(numbers):
        target = _first_code(ch)
        mutants = importlib.import_module(ch.mutants)
        catalogue = [(m[0], m[1], m[2]) for m in mutants.MUTANTS if callable(m[2])]
        nbformat.write(_with_stub(ch), out / f"{ch.prefix}-reference.ipynb")
        plan[f"{ch.prefix}-reference"] = {"chapter": ch.number, "category": "reference", "exercise": None}
        for name, body in HOSTILE.items():
            src = f"def {target.name}(*args, **kwargs):\n    {body.replace('%r', repr(str(ROOT)))}\n"
            sid = f"{ch.prefix}-hostile-{name}"
            nbformat.write(_with_stub(ch, target.name, src), out / f"{sid}.ipynb")
            plan[sid] = {"chapter": ch.number, "category": "hostile", "exercise": target.id}
        picks = rng.sample(catalogue, min(len(catalogue), max(per_chapter - 1 - len(HOSTILE), 0)))
        from graders.core.engine import get
        for exercise_id, short, fn in picks:
            name = get(exercise_id).name
            sid = f"{ch.prefix}-mutant-{exercise_id}-{short}".replace(" ", "_").replace("/", "_")[:90]
            nbformat.write(_with_stub(ch, name, _mutant_source(mutants, fn, name)), out / f"{sid}.ipynb")
            plan[sid] = {"chapter": ch.number, "category": "mutant", "exercise": exercise_id}
    (out / "plan.json").write_text(json.dumps(plan, indent=1))
    return plan


def judge(plan: dict[str, dict], grades: Path) -> list[dict]:
    """Each submission's verdict: did it score what it should?"""
    rows = {r["submission"]: r for r in csv.DictReader((grades / "gradebook.csv").open())}
    verdicts = []
    for sid, p in plan.items():
        r = rows.get(sid)
        if r is None:
            verdicts.append({"id": sid, **p, "ok": False, "why": "missing row"})
            continue
        total, best = float(r["total"]), float(r["max"])
        doc = json.loads((grades / sid / "results.json").read_text())
        graded = {t["number"]: t for t in doc["tests"] if t["max_score"] > 0}
        target = graded.get(p["exercise"]) if p["exercise"] else None
        others_full = all(t["score"] == t["max_score"] for k, t in graded.items() if k != p["exercise"])
        if p["category"] == "reference":
            ok, why = total == best > 0, f"{total:g}/{best:g}"
        elif p["category"] == "mutant":
            ok = target is not None and target["score"] < target["max_score"] and others_full
            why = f"{p['exercise']}: {target['score'] if target else '?'}/{target['max_score'] if target else '?'}"
        else:   # patching numpy also breaks the submission's own later answers: only the attacked one counts
            ok = target is not None and target["score"] == 0 and (others_full or sid.endswith("patch_numpy"))
            why = f"{p['exercise']}: {target['score'] if target else '?'}; others full: {others_full}"
        verdicts.append({"id": sid, **p, "ok": ok, "why": why, "seconds": r.get("seconds")})
    return verdicts


ESCAPE_MARKER = "cv3d-escaped-marker"   # what the write_outside submission appends to the graders


def escaped() -> list[str]:
    """Files outside the sandbox that a hostile submission managed to write."""
    hits = [str(p) for p in (ROOT / "graders").rglob("*.py") if ESCAPE_MARKER in p.read_text(errors="ignore")]
    return hits + (["/tmp/cv3d-escaped"] if Path("/tmp/cv3d-escaped").exists() else [])


def run_batch(subs: Path, grades: Path, workers: int, secret_file: Path | None = None,
              tmpdir: Path | None = None, only: list[str] | None = None) -> float:
    cmd = [sys.executable, "-m", "graders", "batch", str(subs), "--out", str(grades), "--workers", str(workers)]
    if secret_file:
        cmd += ["--secret-file", str(secret_file)]
    if only:
        cmd += ["--only", ",".join(only)]
    # The reference and mutant submissions import the course's `solutions` and tests/mutants, which graded
    # work may not: CV3D_GRADE_REFERENCE lets exactly those in (graders/grading/isolation.py).
    env = dict(os.environ, CV3D_GRADE_REFERENCE="1", **({"TMPDIR": str(tmpdir)} if tmpdir else {}))
    start = time.monotonic()
    subprocess.run(cmd, check=True, cwd=ROOT, stdout=subprocess.DEVNULL, env=env)
    return time.monotonic() - start


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m benchmarks.coursework")
    ap.add_argument("--out", default="/tmp/cv3d-coursework")
    ap.add_argument("--chapters", default="1,2,3,4,5")
    ap.add_argument("--per-chapter", type=int, default=40)
    ap.add_argument("--workers", type=int, default=2)
    args = ap.parse_args(argv)
    out = Path(args.out)
    subs, grades = out / "submissions", out / "grades"
    plan = build(subs, [int(c) for c in args.chapters.split(",")], args.per_chapter)
    secret = out / "secret"
    secret.write_text("benchmark-secret")
    seconds = run_batch(subs, grades, args.workers, secret)
    verdicts = judge(plan, grades)
    table = defaultdict(lambda: [0, 0])
    for v in verdicts:
        table[(v["chapter"], v["category"])][0] += v["ok"]
        table[(v["chapter"], v["category"])][1] += 1
    print(f"{len(plan)} submissions in {seconds / 60:.1f} min with {args.workers} workers: "
          f"{len(plan) / (seconds / 60):.1f} per minute; peak child RSS "
          f"{resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20:.2f} GB")
    print("chapter  category   as expected")
    for (chapter, category), (ok, n) in sorted(table.items()):
        print(f"{chapter:>7}  {category:<9}  {ok}/{n}")
    for v in verdicts:
        if not v["ok"]:
            print("NOT AS EXPECTED:", v)
    print("files written outside the sandbox:", escaped() or "none")
    return 0


if __name__ == "__main__":
    sys.exit(main())
