"""Graded coursework: the student edition (no solutions; from a fresh venv every notebook sets up, and those it changes run to their last swapped demo), the
Gradescope autograder (run as Gradescope runs it, valid results.json in every failure mode) and the
batch grader (every row present, resumable)."""
from __future__ import annotations

import ast
import csv
import json
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import nbformat
import pytest

from graders.core.chapters import READY
from graders.grading.release import gradescope_bundle, student_release
from graders.grading.standins import KEPT, TWINS
from notebook_stubs import ROOT, solved as _solved

# Tests that use the student release (a module-scoped fixture) run on one worker of a parallel run, so it is built once
# (conftest.py, ONE_WORKER).

SITE = next(p for p in sys.path if p.endswith("site-packages") and Path(p, "numpy").exists())


def _bodies(source: str) -> dict[str, str]:
    """Every function body of `source` (docstring dropped, AST-normalised) with >= 3 statements: body -> name."""
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return {}
    out = {}
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            body = node.body[1:] if ast.get_docstring(node) else node.body
            if len(body) >= 3:
                out["\n".join(ast.unparse(stmt) for stmt in body)] = node.name
    return out


def _code_of(path: Path) -> str:
    if path.suffix == ".ipynb":
        cells = nbformat.read(path, as_version=4).cells
        return "\n".join(c.source for c in cells if c.cell_type == "code" and not c.source.lstrip().startswith(("%", "!")))
    return path.read_text(errors="ignore")


@pytest.fixture(scope="module")
def release(tmp_path_factory):
    return student_release(tmp_path_factory.mktemp("rel") / "course")


def test_release_has_no_reference_code(release):
    assert not (release / "solutions").exists()
    texts = {p: p.read_text(errors="ignore") for p in release.rglob("*") if p.is_file() and p.suffix in (".py", ".ipynb", ".md", ".toml")}
    mentions = [str(p) for p, t in texts.items() if "import solutions" in t or "from solutions" in t]
    assert not mentions, mentions
    reference = {}
    for path in (ROOT / "solutions").rglob("*.py"):
        reference |= _bodies(path.read_text())
    assert len(reference) > 100     # the check has something to find
    leaked = [f"{p.relative_to(release)}: {name} (reference {reference[body]})"
              for p in texts if p.suffix in (".py", ".ipynb")
              for body, name in _bodies(_code_of(p)).items() if body in reference]
    assert not leaked, leaked
    for ch in READY:
        assert (release / ch.notebook).exists() and (release / "graders" / ch.prefix).is_dir()


# ---------------------------------------------------------------- sealed questions (graders.grading.seal)

def _questions() -> dict[str, tuple[object, str, bool]]:
    """Every value question built by numeric_question/choice_question: id -> (its plain answer, its model answer,
    whether the answer is the option list itself). 4.2 is not among them: its answer is read from pycolmap's defaults when it is graded."""
    import numpy as np
    from graders.core.engine import chapter
    out = {}
    for ch in READY:
        for ex in chapter(ch.key):
            builder = ex.cases.__qualname__.split(".")[0]
            if ex.value and builder in ("numeric_question", "choice_question"):
                case = next(iter(ex.cases(np.random.default_rng(0))))
                answer = case.expected if isinstance(case.expected, list) else np.asarray(case.expected, float).tolist()
                # answers that are a run of the options in their listed order (7.2, 7.13) are no leak: the learner
                # sees the options
                visible = builder == "choice_question" and "|".join(answer) in "|".join(_options(case))
                out[ex.id] = (answer, ex.explanation, visible)
    return out


def _options(case) -> list[str]:
    """A choice question's options, lower-cased, in the order the question lists them."""
    import inspect
    listed = inspect.getclosurevars(case.convert).nonlocals["listed"]
    return [o.strip('"').strip().lower() for o in listed.split('", "')]


def _spellings(answer) -> set[str]:
    """How an answer can be written in a file: a list of choices or numbers in Python or JSON, a full-precision
    float. Short scalars (2, 0.5) and short lists of small integers ([0, 1, 2]) are left out: they occur everywhere;
    the AST check below covers them."""
    import numpy as np
    if isinstance(answer, list) and answer and isinstance(answer[0], str):
        forms = set()
        for case in (str.lower, str.upper, str.title, lambda a: a):
            items = [case(a) for a in answer]
            forms |= {repr(items), json.dumps(items), ", ".join(repr(a) for a in items), ", ".join(json.dumps(a) for a in items)}
        return forms
    values = np.ravel(np.asarray(answer, float)).tolist()
    if len(values) <= 3 and all(v == int(v) and abs(v) < 10 for v in values):
        return set()
    if len(values) == 1:
        text = repr(values[0])
        return {text} if len(text.strip("-0.").replace(".", "")) >= 6 else set()
    forms = set()
    for fmt in (repr, lambda v: repr(int(v)) if v == int(v) else repr(v), lambda v: f"{v:g}"):
        items = [fmt(v) for v in values]
        forms |= {"[" + ", ".join(items) + "]", "(" + ", ".join(items) + ")", "[" + ",".join(items) + "]"}
    return forms


def _release_texts(release: Path) -> dict[Path, str]:
    return {p: p.read_text(errors="ignore") for p in release.rglob("*")
            if p.is_file() and p.suffix in (".py", ".ipynb", ".md", ".toml", ".json", ".txt", ".cfg")}


def test_release_holds_no_question_answer(release):
    questions = _questions()
    assert len(questions) > 80          # every chapter's CONCEPT/DESIGN questions: the check has something to find
    texts = _release_texts(release)
    leaks = []
    for ident, (answer, explanation, visible) in questions.items():
        for form in set() if visible else _spellings(answer):
            leaks += [f"{ident}: answer {form} in {p.relative_to(release)}" for p, t in texts.items() if form in t]
        words = explanation.split()          # the model answer, in any run of 8 of its words
        for i in range(0, max(len(words) - 8, 0) + 1, 4):
            run = " ".join(words[i:i + 8])
            if len(run) > 40:   # notebooks/ and docs/ are the lesson, shipped as they are: what they teach is no leak
                leaks += [f"{ident}: model answer {run!r} in {p.relative_to(release)}" for p, t in texts.items()
                          if run in t and p.relative_to(release).parts[0] not in ("notebooks", "docs")]
    assert not leaks, "\n".join(leaks)
    # what a grep cannot see, an answer computed in the file (`expected=1.5 * SYNC[...]`): every builder call of
    # the release takes its answer from the sealed file, and its model answer is empty
    from graders.grading.seal import QUESTIONS, _builder_calls, _param_index
    seen = set()
    for path in (release / "graders").rglob("*.py"):
        for call, builder, ident in _builder_calls(ast.parse(path.read_text())):
            args = {kw.arg: kw.value for kw in call.keywords}
            for name in (QUESTIONS[builder], "explanation"):
                node = args.get(name)
                if node is None:
                    node = call.args[_param_index(builder, name)]
                plain = ast.unparse(node)
                assert plain in (f"sealed({ident!r})", "''"), f"{path}: {ident} {name}={plain}"
            seen.add(ident)
    assert seen == set(questions)


def test_release_questions_still_tell_right_from_wrong(release, tmp_path):
    """In the release, each question's right answer passes (and opens its model answer) and a wrong one fails,
    with the hints that do not need the answer; run by the release's own graders."""
    questions = _questions()
    (tmp_path / "answers.json").write_text(json.dumps({k: v[0] for k, v in questions.items()}))
    probe = """
import json, sys
import numpy as np
import graders
from graders import check
assert graders.__file__.startswith(sys.argv[2]), graders.__file__
bad = []
for ident, answer in json.load(open(sys.argv[1])).items():
    right = check(ident, answer, seed=0)
    if not right.passed or "sealed" in right.explanation[:40]:
        bad.append((ident, "right answer", right.status, right.explanation[:40]))
    if isinstance(answer[0] if isinstance(answer, list) and answer else answer, str):
        wrong = answer[1:] + answer[:1]
    else:
        wrong = (np.asarray(answer, float) * 1.5 + 1.0).tolist()
    if wrong != answer:
        result = check(ident, wrong, seed=0)
        if result.passed or "sealed" not in result.explanation:
            bad.append((ident, "wrong answer", result.status, result.explanation[:40]))
# the tolerance still holds: 7.14's 0.866 m given as 0.87 (0.5 % off, tol 2 %) passes; 0.95 (10 %) does not
bad += [("7.14", a) for a, ok in ((0.87, True), (0.95, False)) if check("7.14", a, seed=0).passed != ok]
print(json.dumps(bad))
print(check("7.2", ["excellent", "acceptable", "acceptable"], seed=0).cases[0].hint)
"""
    out = subprocess.run([sys.executable, "-c", probe, str(tmp_path / "answers.json"), str(release / "graders")],
                         capture_output=True, text=True, cwd=tmp_path, timeout=300,
                         env=dict(os.environ, PYTHONPATH=str(release)))
    assert out.returncode == 0, out.stderr[-3000:]
    bad, hint = out.stdout.splitlines()[-2:]
    assert json.loads(bad) == []
    assert hint.startswith("1.4 px is above 1 px")        # a scenario's hint fires on that scenario's wrong choice


# ---------------------------------------------------------------- stand-ins that are a solution (graders.grading.standins)

# The CODE exercises whose stand-in is the grader's own implementation (not a call to cv2/pycolmap/kornia, which
# graded mode refuses) and which the release still ships: graders.grading.standins.KEPT, each with why it stays.
# 51: 60 before 2.6, 2.7, 2.8, 2.9 and 4.6 got their library twins, 55 before 4.14's stand-in was seen to be the
# OpenCV one it is (its IncrementalSfM class calls cv2; standins.solution_code now follows the classes a stand-in
# builds), 54 before 5.6's, 5.7's and 5.8's twins (cv2.projectPoints and its Jacobian). A stand-in taken out must
# leave KEPT (and SHIPPED_CEILING come down to it); a new one that is a solution fails the test until it is taken out
# or listed there with its reason.
SHIPPED_SOLUTIONS = frozenset(KEPT)
SHIPPED_CEILING = 51          # only goes down


def test_shipped_solutions_only_go_down():
    assert len(KEPT) <= SHIPPED_CEILING, f"{len(KEPT)} stand-ins that are a solution ship, more than {SHIPPED_CEILING}"
    assert all(isinstance(why, str) and len(why) > 20 for why in KEPT.values()), "each one says why it stays"


def _twin_exercises() -> list[tuple[object, str, object]]:
    """(chapter, exercise id, twin function) of each stand-in standins.TWINS swaps in the release."""
    import importlib
    import inspect
    from graders.core import engine
    out = []
    for (rel, name), twin in TWINS.items():     # a chapter's module, or graders/oracles/ (5.6's bal_project)
        module = importlib.import_module(rel.removesuffix(".py").replace("/", "."))
        found = [(ch, ex.id, getattr(module, twin)) for ch in READY for ex in engine.chapter(ch.key)
                 if ex.fallback is not None and inspect.unwrap(ex.fallback) is getattr(module, name)]
        assert found, (rel, name)
        out += found
    return out


def test_every_twin_is_a_library_row_of_its_exercise():
    """A twin (standins.TWINS) replaces, in the release, a stand-in that is often also the local check's oracle:
    it must be one of its exercise's contract LIBRARY rows (tests/chapters/test_contract.py: full marks on every
    case of the fixed seeds), so the release's demos and local checks see the same answer to the tolerance."""
    import importlib
    for ch, ident, twin in _twin_exercises():
        library = importlib.import_module(f"mutants.{ch.prefix}_contract").LIBRARY
        assert any(row.exercise_id == ident and row.fn is twin for row in library), (ident, twin.__name__)


def test_release_ships_no_solution_standin_but_the_listed_ones(release):
    from graders.grading.standins import body_key, solution_bodies
    bodies = solution_bodies([ch.number for ch in READY])
    assert len(bodies) > 100                 # gt_intrinsics_from_homographies, imu._model, ...: something to find
    found: dict[str, set[str]] = {}
    for path in release.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and body_key(node) in bodies:
                ident, name = bodies[body_key(node)]
                found.setdefault(ident, set()).add(f"{path.relative_to(release)}:{name}")
    new = {i: sorted(found[i]) for i in set(found) - SHIPPED_SOLUTIONS}
    assert not new, f"stand-ins that are an exercise's solution, shipped in the student release: {new}"
    assert set(found) == SHIPPED_SOLUTIONS, f"no longer shipped (take them off SHIPPED_SOLUTIONS): {SHIPPED_SOLUTIONS - set(found)}"


def test_release_installs_in_a_fresh_venv_and_every_notebook_sets_up(release, tmp_path):
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)  # pip and setuptools come with the pinned packages
    pth = next((venv / "lib").glob("python3.*/site-packages"))
    (pth / "_course_dependencies.pth").write_text(SITE + "\n")   # the pinned packages, not this checkout
    py = str(venv / "bin" / "python")
    subprocess.run([py, "-m", "pip", "install", "-q", "--no-deps", "--no-build-isolation", "--no-index", "-e", str(release)],
                   check=True, timeout=300, cwd=tmp_path)
    probe = subprocess.run([py, "-c", "import graders, graders.core.chapters as c; print(graders.__file__, len(c.READY));"
                            "import solutions"], capture_output=True, text=True, cwd=tmp_path)
    assert "ModuleNotFoundError: No module named 'solutions'" in probe.stderr, probe.stderr + probe.stdout
    assert probe.stdout.startswith(str(release / "graders")), probe.stdout   # the release, not this checkout
    changed: dict[str, list[str]] = {}           # notebook -> the exercises whose stand-in the release swapped
    for ch, ident, _ in _twin_exercises():
        changed.setdefault(str(release / ch.notebook), []).append(ident)
    env = dict(os.environ, MPLBACKEND="Agg", COURSE_STATIC_PLOTS="1")
    out = subprocess.run([py, "-c", RELEASE_RUNNER, json.dumps(changed),
                          *[str(release / c.notebook) for c in READY]], capture_output=True, text=True, timeout=900,
                         cwd=tmp_path, env=env)
    assert out.returncode == 0, out.stderr[-4000:]
    assert out.stdout.count("RELEASE-RAN ") == len(changed) and out.stdout.count("RELEASE-SET-UP ") == len(READY) - len(changed), \
        out.stdout[-2000:]


# In the release's venv, each notebook's first code cell (its imports and set-up) runs, and every name the notebook
# reads from a `graders` module must exist in the release: sealing drops the module-level names nothing in the release
# uses, and a name only a notebook uses would otherwise fail in a learner's kernel. The notebooks of the chapters the
# release changes beyond its questions (a stand-in swapped for its library twin) run from the top to their last cell
# that use()s a swapped exercise (02 to its end; 05 to 5.6's second demo, cell 75 of 120; 04 only to 4.6's demo: its
# Sacré-Cœur half never touches the twin but for the grader's pair ranking, whose local checks on the twin the
# fairness sweep covers). The untouched notebooks run whole against this repository's graders (nbval) and solved
# (tests/chapters/test_notebooks.py): the student edition's graders differ only in their sealed questions (tested
# above) and twins.
RELEASE_RUNNER = """
import ast, importlib, json, re, sys, types
import nbformat
from nbclient import NotebookClient

def code_of(cell):
    return "\\n".join(line for line in cell.source.splitlines() if not line.lstrip().startswith(("%", "!")))

swapped = json.loads(sys.argv[1])
for path in sys.argv[2:]:
    nb = nbformat.read(path, as_version=4)
    if path in swapped:
        uses = [i for i, c in enumerate(nb.cells) if c.cell_type == "code"
                and any(re.search(r"use\\(\\s*[\\"']%s[\\"']" % re.escape(ident), c.source) for ident in swapped[path])]
        assert uses, (path, swapped[path])
        nb.cells = nb.cells[:uses[-1] + 1]
        NotebookClient(nb, timeout=120, kernel_name="python3", resources={"metadata": {"path": "."}}).execute()
        print("RELEASE-RAN", path, len(nb.cells))
        continue
    cells = [code_of(c) for c in nb.cells if c.cell_type == "code"]
    ns = {}
    exec(compile(cells[0], path, "exec"), ns)
    missing = []
    for code in cells:
        try:
            tree = ast.parse(code)
        except SyntaxError:
            continue
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name):
                module = ns.get(node.value.id)
                if isinstance(module, types.ModuleType) and module.__name__.startswith("graders") \\
                        and not hasattr(module, node.attr):
                    missing.append(node.value.id + "." + node.attr)
            elif isinstance(node, ast.ImportFrom) and (node.module or "").startswith("graders"):
                module = importlib.import_module(node.module)
                for alias in node.names:
                    if not hasattr(module, alias.name):
                        try:
                            importlib.import_module(node.module + "." + alias.name)
                        except ImportError:
                            missing.append(node.module + "." + alias.name)
    assert not missing, (path, sorted(set(missing)))
    print("RELEASE-SET-UP", path)
"""


def _autograder(tmp_path: Path, submission: dict[str, str | bytes], secret: bytes | None, budget: float | None = None):
    root = tmp_path / "autograder"
    for d in ("source", "submission", "results"):
        (root / d).mkdir(parents=True)
    with zipfile.ZipFile(gradescope_bundle(tmp_path / "autograder.zip", 1, secret, budget,
                                           allow_missing_data=True)) as z:
        z.extractall(root / "source")
    run = root / "source" / "run_autograder"
    run.chmod(0o755)
    for name, content in submission.items():
        (root / "submission" / name).write_bytes(content if isinstance(content, bytes) else content.encode())
    # CV3D_GRADE_REFERENCE: the submissions here are the course's reference (`from solutions import ...`), which
    # graded mode hides from learners; this switch, never set to grade students, lets exactly that in.
    env = dict(os.environ, AUTOGRADER_ROOT=str(root), AUTOGRADER_PYTHON=sys.executable, CV3D_GRADE_REFERENCE="1")
    proc = subprocess.run([str(run)], env=env, capture_output=True, text=True, timeout=900)
    assert proc.returncode == 0 and proc.stdout == "", proc.stdout[-2000:] + proc.stderr[-2000:]
    return json.loads((root / "results" / "results.json").read_text())


def test_gradescope_autograder_grades_a_solved_notebook_with_hidden_cases(tmp_path):
    nb = nbformat.writes(_solved(ROOT / "notebooks" / "01_camera_models.ipynb")).encode()
    doc = _autograder(tmp_path, {"01_camera_models.ipynb": nb}, b"course-secret")
    assert doc["score"] == doc["max_score"] > 0
    assert doc["visibility"] == "after_due_date"          # no total before the due date
    graded = [t for t in doc["tests"] if t["max_score"] > 0]
    assert graded and all(t["visibility"] == "after_due_date" for t in graded)
    assert any("feedback" in t["name"] and t["visibility"] == "visible" for t in doc["tests"])


@pytest.mark.parametrize("submission, phrase", [
    ({}, "No notebook"),
    ({"01_camera_models.ipynb": "{ not a notebook"}, "could not read"),
    ({"01_camera_models.py": "def project_points(*a):\n    while True:\n        pass\n"}, "time limit"),
], ids=["empty", "unparsable", "loops"])
def test_gradescope_autograder_writes_valid_json_in_every_failure_mode(tmp_path, submission, phrase):
    doc = _autograder(tmp_path, submission, b"s", budget=60)
    assert doc["score"] == 0
    text = doc.get("output", "") + " ".join(t["output"] for t in doc["tests"])
    assert phrase in text, text[:2000]


def test_batch_grades_every_submission_and_resumes(tmp_path):
    subs, out = tmp_path / "subs", tmp_path / "grades"
    (subs / "dora").mkdir(parents=True)
    nbformat.write(_solved(ROOT / "notebooks" / "01_camera_models.ipynb"), subs / "alice.ipynb")
    (subs / "bob.py").write_text("import os\nos._exit(3)\ndef project_points(*a):\n    os._exit(3)\n")
    (subs / "carol.ipynb").write_text("not json")
    cmd = [sys.executable, "-m", "graders", "batch", str(subs), "--out", str(out), "--chapter", "1"]
    reference = dict(os.environ, CV3D_GRADE_REFERENCE="1")     # alice is the reference: see _autograder
    first = subprocess.run(cmd, capture_output=True, text=True, timeout=900, cwd=ROOT, env=reference)
    assert first.returncode == 0, first.stderr[-3000:]
    rows = {r["submission"]: r for r in csv.DictReader((out / "gradebook.csv").open())}
    assert set(rows) == {"alice", "bob", "carol", "dora"}
    assert float(rows["alice"]["total"]) == float(rows["alice"]["max"]) > 0
    assert all(float(rows[s]["total"]) == 0 for s in ("bob", "carol", "dora"))
    assert rows["dora"]["status"] == "error" and "no notebook" in rows["dora"]["error"]
    assert "1.5" in rows["alice"]
    for sid in rows:
        assert json.loads((out / sid / "results.json").read_text())["extra_data"]["complete"]
    again = subprocess.run(cmd, capture_output=True, text=True, timeout=300, cwd=ROOT, env=reference)
    assert "4 already graded, 0 to grade" in again.stdout, again.stdout


def test_gradescope_bundle_carries_the_data_its_chapter_grades_on(tmp_path):
    from graders.kit import datasets
    from graders.grading.release import BUNDLE_DATA, chapter_datasets
    assert chapter_datasets(1) == ["chessboard"] and chapter_datasets(4) == ["sacre_coeur", "sceaux_castle"]
    if not datasets.available("chessboard"):
        pytest.skip("the chessboard views are not in $COURSE_DATA or the cache")
    with zipfile.ZipFile(gradescope_bundle(tmp_path / "autograder.zip", 1)) as z:
        names = set(z.namelist())
        config = json.loads(z.read("autograder.json"))
    assert config["datasets"] == ["chessboard"]
    assert {f"{BUNDLE_DATA}/{f['path']}" for f in datasets.info("chessboard")["files"]} <= names


def test_gradescope_without_its_data_shows_a_failed_test(tmp_path, monkeypatch):
    """A bundle whose dataset is missing (built --without-data, or deleted) never drops real-data cases
    silently: every results.json it writes carries a visible failed test naming the dataset."""
    from graders.grading.release import BUNDLE_DATA, gradescope_run
    monkeypatch.setenv("COURSE_DATA", str(tmp_path / "nowhere"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "no-cache"))
    root = tmp_path / "autograder"
    for d in ("source", "submission", "results"):
        (root / d).mkdir(parents=True)
    with zipfile.ZipFile(gradescope_bundle(tmp_path / "autograder.zip", 1, None, None, allow_missing_data=True)) as z:
        z.extractall(root / "source")
    assert not list((root / "source").glob(f"{BUNDLE_DATA}/**/*.*"))
    assert gradescope_run(root) == 0              # an empty submission: the quickest full run
    doc = json.loads((root / "results" / "results.json").read_text())
    failed = [t for t in doc["tests"] if "chessboard" in t["name"]]
    assert failed and failed[0]["status"] == "failed" and failed[0]["visibility"] == "visible"
    assert "not run" in failed[0]["output"] and "No notebook" in doc.get("output", "")


def test_release_readme_lists_only_what_the_release_holds(tmp_path):
    import re
    rel = student_release(tmp_path / "course", [1, 3])
    text = (rel / "README.md").read_text()
    for instructor_only in ("solutions", "make bench", "tests/", "benchmarks", "Teaching with it", "For contributors",
                            "python -m graders batch", "--secret-file"):
        assert instructor_only not in text, instructor_only
    links = re.findall(r"\]\(([^)#]+)\)", text)
    assert "notebooks/01_camera_models.ipynb" in links and "notebooks/03_features.ipynb" in links
    missing = [link for link in links if not link.startswith("http") and not (rel / link).exists()]
    assert not missing, missing                      # no link to a chapter (or file) this edition lacks
    assert "notebooks/02_epipolar.ipynb" not in text
    assert "answers are sealed in this edition" in text      # what a check of a question does here
    assert sorted(p.name for p in (rel / "docs").iterdir()) == ["CONVENTIONS.md", "ENGINE.md"]   # no instructor log
