"""The student release's questions without their answers (graders.core.sealed says how they are checked).

`seal_questions(pkg, numbers)` runs on a release's copy of `graders/`: every chapter module that builds
`numeric_question`/`choice_question`s is rewritten (from its AST, so comments, which quote answers, go too)
with `expected=`/`answers=` replaced by `sealed("ID")` and `explanation=` by "", then stripped of the
module-level names nothing uses any more (the tables and helpers that computed the answers); the sealed
answers go to `graders/sealed.json`. The instructor's repository is never changed: self-study there keeps
plain answers, hints and model answers, and graded mode (run from it) judges with the true answers.
"""
from __future__ import annotations

import ast
import inspect
import json
import secrets
from pathlib import Path

import numpy as np

from graders.core import compare, engine, sealed
from graders.core.chapters import by_number

QUESTIONS = {"numeric_question": "expected", "choice_question": "answers"}   # builder -> its answer parameter


def _param_index(builder: str, name: str) -> int:
    return list(inspect.signature(getattr(engine, builder)).parameters).index(name)


def _builder_calls(tree: ast.AST) -> list[tuple[ast.Call, str, str]]:
    """(call, builder, exercise id) for every question-builder call with a literal id."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id in QUESTIONS:
            args = {kw.arg: kw.value for kw in node.keywords}
            ident = args.get("id", node.args[0] if node.args else None)
            if isinstance(ident, ast.Constant) and isinstance(ident.value, str):
                out.append((node, node.func.id, ident.value))
    return out


def _set_arg(call: ast.Call, builder: str, name: str, value: ast.expr) -> None:
    for kw in call.keywords:
        if kw.arg == name:
            kw.value = value
            return
    index = _param_index(builder, name)
    if index < len(call.args):
        call.args[index] = value
    else:
        call.keywords.append(ast.keyword(arg=name, value=value))


def _defined(stmt: ast.stmt) -> set[str]:
    if isinstance(stmt, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
        return {stmt.name}
    targets = stmt.targets if isinstance(stmt, ast.Assign) else [stmt.target] if isinstance(stmt, ast.AnnAssign) else []
    return {n.id for t in targets for n in ast.walk(t) if isinstance(n, ast.Name)}


def _used(nodes) -> set[str]:
    names = set()
    for node in nodes:
        for sub in ast.walk(node):
            if isinstance(sub, ast.Name):
                names.add(sub.id)
            elif isinstance(sub, ast.Attribute):
                names.add(sub.attr)
            elif isinstance(sub, ast.alias):
                names.add(sub.name.split(".")[-1])
    return names


def _drop_unused(tree: ast.Module, used_elsewhere: set[str]) -> None:
    """Remove module-level definitions (functions, classes, assignments) that nothing in the module or the
    rest of the release refers to, until none is left."""
    while True:
        body = tree.body
        dead = []
        for i, stmt in enumerate(body):
            names = _defined(stmt)
            if not names or names & used_elsewhere or "__all__" in names:
                continue
            if not names & _used(s for j, s in enumerate(body) if j != i):
                dead.append(i)
        if not dead:
            return
        tree.body = [s for i, s in enumerate(body) if i not in dead]


def _release_names(root: Path) -> dict[Path, set[str]]:
    """Every identifier each of the release's Python files and notebooks (code cells) uses."""
    import nbformat
    names = {py: _used([ast.parse(py.read_text(encoding="utf-8"))]) for py in root.rglob("*.py")}
    for nb in root.rglob("*.ipynb"):
        names[nb] = set()
        for cell in nbformat.read(nb, as_version=4).cells:
            code = "\n".join(line for line in cell.source.splitlines() if not line.lstrip().startswith(("%", "!")))
            if cell.cell_type == "code":
                try:
                    names[nb] |= _used([ast.parse(code)])
                except SyntaxError:
                    pass
    return names


def seal_source(source: str, used_elsewhere: set[str]) -> tuple[str, list[str]]:
    """`source` with its questions' answers and model answers replaced by `sealed(...)` and its now unused
    definitions dropped; and the ids it sealed."""
    tree = ast.parse(source)
    ids = []
    for call, builder, ident in _builder_calls(tree):
        _set_arg(call, builder, QUESTIONS[builder],
                 ast.Call(func=ast.Name("sealed", ast.Load()), args=[ast.Constant(ident)], keywords=[]))
        _set_arg(call, builder, "explanation", ast.Constant(""))
        ids.append(ident)
    if not ids:
        return source, []
    doc = [tree.body.pop(0)] if ast.get_docstring(tree) else []
    future = [s for s in tree.body if isinstance(s, ast.ImportFrom) and s.module == "__future__"]
    rest = [s for s in tree.body if s not in future]
    imp = ast.parse("from graders.core.sealed import sealed").body
    tree.body = doc + future + imp + rest
    _drop_unused(tree, used_elsewhere)
    return ast.unparse(ast.fix_missing_locations(tree)) + "\n", ids


def _metric_name(fn) -> str:
    for name in ("relative", "max_abs"):
        if fn is getattr(compare, name):
            return name
    return "unit" if fn is compare.up_to_scale else ""


def _spec(ex: engine.Exercise) -> dict:
    """The sealed form of a value question registered by numeric_question/choice_question."""
    case = next(iter(ex.cases(np.random.default_rng(0))))
    salt = secrets.token_hex(16)
    if isinstance(case.expected, list):                        # choice_question: lower-cased answers
        return sealed.seal_choice(ex.id, case.expected, ex.explanation, salt)
    metric = _metric_name(case.metric)
    expected = np.asarray(case.expected, float)
    if not metric:
        raise ValueError(f"{ex.id}: no band for the metric {case.metric!r}")
    return sealed.seal_number(ex.id, expected, metric, case.tol, ex.explanation, salt)


def seal_questions(root: Path, numbers: list[int]) -> list[str]:
    """Seal every question of the release at `root` (its `graders/` copied from this repository); returns the ids."""
    pkg = root / "graders"
    specs, done = {}, []
    names = _release_names(root)
    for n in numbers:
        ch = by_number(n)
        registered = {ex.id: ex for ex in engine.chapter(ch.key)}
        for py in sorted((pkg / ch.prefix).glob("*.py")):
            text = py.read_text(encoding="utf-8")
            if not any(b + "(" in text for b in QUESTIONS):
                continue
            new, ids = seal_source(text, set().union(*(v for k, v in names.items() if k != py)))
            for ident in ids:
                specs[ident] = _spec(registered[ident])
            py.write_text(new, encoding="utf-8")
            done += ids
    (pkg / sealed.SEALED_FILE.name).write_text(json.dumps(specs, indent=0, sort_keys=True))
    return done
