"""The house rules of `graders` (docs/ENGINE.md, "Packages by role"), checked on the source's AST:
no import cycle, no import a row of `graders.layers.LAYERS` does not allow, modules and functions small."""
from __future__ import annotations

import ast
from pathlib import Path

from graders.layers import BY_NAME, LAYERS, layer_of, markdown

ROOT = Path(__file__).resolve().parents[2]
GRADERS = ROOT / "graders"
MAX_MODULE_LINES = 600
MAX_FUNCTION_LINES = 80


def _module_name(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


MODULES = {_module_name(p): p for p in GRADERS.rglob("*.py")}


def _imports(name: str, path: Path) -> set[str]:
    """The modules of graders that `name` imports anywhere in its body (function-level imports too):
    `from graders.kit import scene` is an import of graders.kit.scene, a submodule."""
    package = name if path.name == "__init__.py" else name.rsplit(".", 1)[0]
    found: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = package.rsplit(".", node.level - 1)[0] if node.level else ""
            module = ".".join(p for p in (base, node.module or "") if p)
            subs = {f"{module}.{a.name}" for a in node.names} & MODULES.keys()
            found |= subs or {module}
    return {m for m in found if m in MODULES and m != name}


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan), each a cycle of imports."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in graph:
        if v not in index:
            visit(v)
    return found


def _is_package_init(importer: str, imported: str) -> bool:
    # A package's __init__ importing its own modules (and they its public names) is how a package is made.
    return imported.startswith(importer + ".") or importer.startswith(imported + ".")


def test_no_import_cycle_in_graders():
    graph = {v: {w for w in ws if not _is_package_init(v, w)} for v, ws in GRAPH.items()}
    assert not _cycles(graph), _cycles(graph)


def test_no_upward_import_in_graders():
    offenders = []
    for name, imported in GRAPH.items():
        row = layer_of(name) if name != "graders" else "entry"
        for other in imported:
            target = layer_of(other) if other != "graders" else "entry"
            if target != row and target not in BY_NAME[row].may_import:
                offenders.append(f"{name} ({row}) imports {other} ({target})")
    assert not offenders, "\n".join(sorted(offenders))


def test_every_module_of_graders_has_a_row():
    rows = {layer.name for layer in LAYERS}
    assert {layer_of(n) for n in MODULES if n != "graders"} <= rows


def test_the_layer_check_can_fail():
    # The checks above on a made-up graph: a cycle, and kit importing core (upward).
    assert _cycles({"a": {"b"}, "b": {"a"}, "c": set()}) == [["a", "b"]]
    assert "core" not in BY_NAME["kit"].may_import


def test_engine_doc_shows_the_table():
    assert markdown() in (ROOT / "docs" / "ENGINE.md").read_text(), \
        "docs/ENGINE.md's package table differs from graders/layers.py: paste `python -m graders.layers`"


def test_modules_and_functions_are_small():
    big = []
    for name, path in MODULES.items():
        text = path.read_text()
        if text.count("\n") > MAX_MODULE_LINES:
            big.append(f"{name}: {text.count(chr(10))} lines")
        for node in ast.walk(ast.parse(text)):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                n = node.end_lineno - node.lineno + 1
                if n > MAX_FUNCTION_LINES:
                    big.append(f"{name}.{node.name}: {n} lines")
    assert not big, "\n".join(big)


def test_a_chapter_package_imports_no_heavy_library_until_used():
    # Every `python -m graders check` imports its chapter twice (the parent to list the exercises, the worker to
    # grade them), and most of the suite's graders are chapter 1's: scipy.optimize, scipy.spatial (with scipy.linalg
    # and scipy.sparse) and torch are imported in the functions that use them (1.2 -> 0.5 CPU s per import).
    import subprocess
    import sys
    heavy = ("scipy.optimize", "scipy.sparse", "scipy.spatial", "scipy.linalg", "scipy.stats", "scipy.ndimage", "torch")
    code = ("import sys, graders.cli, graders.grading.worker, graders.ch01_camera_models, graders.ch02_epipolar; "
            f"print([m for m in {heavy!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert out.returncode == 0, out.stderr[-2000:]
    assert out.stdout.strip() == "[]", f"imported at start-up: {out.stdout.strip()}"
