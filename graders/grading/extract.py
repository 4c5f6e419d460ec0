"""Pull a learner's definitions out of a notebook or module without running its other cells.

Only imports, function and class definitions, ALL_CAPS constants and assignments to the names of
value exercises (answers to questions) are kept. Demo cells, plots, `check(...)` calls and
`name = use(...)` lines are dropped: the grader must judge the learner's own function, never the
stand-in that `use` returns.
"""
from __future__ import annotations

import ast
import json
from dataclasses import dataclass, field
from pathlib import Path


@dataclass
class Extracted:
    source: str
    problems: list[str] = field(default_factory=list)  # cells that could not be parsed, ...


def _cells(path: Path) -> list[str]:
    if path.suffix == ".ipynb":
        nb = json.loads(path.read_text(encoding="utf-8"))
        cells = []
        for cell in nb.get("cells", []):
            if cell.get("cell_type") == "code":
                src = cell.get("source", "")
                cells.append("".join(src) if isinstance(src, list) else src)
        return cells
    return [path.read_text(encoding="utf-8")]


def _strip_magics(src: str) -> str:
    # IPython magics and shell escapes are not Python; blank them out keeping line numbers.
    return "\n".join("" if line.lstrip().startswith(("%", "!")) else line for line in src.splitlines())


def _calls(node: ast.AST, names: set[str]) -> bool:
    return any(isinstance(n, ast.Call) and isinstance(n.func, ast.Name) and n.func.id in names
               for n in ast.walk(node))


def _keep(stmt: ast.stmt, value_names: set[str]) -> bool:
    if isinstance(stmt, (ast.Import, ast.ImportFrom, ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
        return True
    if isinstance(stmt, (ast.Assign, ast.AnnAssign)):
        targets = stmt.targets if isinstance(stmt, ast.Assign) else [stmt.target]
        names = [t.id for t in targets if isinstance(t, ast.Name)]
        if len(names) != len(targets) or _calls(stmt, {"use", "check"}):
            return False
        return all(n in value_names or (n.isupper() and len(n) > 1) for n in names)
    return False


def read_cells(path: str | Path) -> tuple[list[str], list[str]]:
    """The code cells of `path` (.ipynb, or a .py as one cell) and the problems met reading it."""
    path = Path(path)
    try:
        return _cells(path), []
    except Exception as exc:
        return [], [f"could not read {path.name}: {exc}"]


def extract(path: str | Path, value_names: set[str] = frozenset(),
            read: tuple[list[str], list[str]] | None = None) -> Extracted:
    """The learner's definitions from `path` (.ipynb or .py) as one module source.
    read: `read_cells(path)` when the caller has read the file already (the file is read once)."""
    cells, problems = read if read is not None else read_cells(path)
    out = Extracted(source="", problems=list(problems))
    kept = []
    for i, src in enumerate(cells, 1):
        src = _strip_magics(src)
        try:
            tree = ast.parse(src)
        except SyntaxError as exc:
            out.problems.append(f"code cell {i} has a syntax error (line {exc.lineno}: {exc.msg}); it was skipped")
            continue
        for stmt in tree.body:
            if _keep(stmt, set(value_names)):
                decorated = getattr(stmt, "decorator_list", None)  # segments start at `def`, not at `@`
                kept.append(ast.unparse(stmt) if decorated else ast.get_source_segment(src, stmt) or ast.unparse(stmt))
    out.source = "\n\n".join(kept) + "\n" if kept or not problems else ""
    return out
