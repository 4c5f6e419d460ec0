"""What graded mode checks in the learner's source where the OS cannot hide the grader's files.

In process mode (no namespaces: not root, or no `unshare`) the learner process still gets stand-ins for
`graders` and the refused libraries, but the real files stay readable to it: code that edits its import
path, removes the import hook, loads a module by hand or digs through interpreter internals could reach
them. `findings(source, name, refused)` lists such uses in the code an exercise runs — the function
`name` and every top-level function or class it refers to, transitively — and every use of a refused
library or of the course's packages there. It is a weaker guard than an absent file (a determined
learner can hide intent from an AST), which is why the results say so.
"""
from __future__ import annotations

import ast
import re

COURSE = ("graders", "solutions")
# Import machinery and interpreter internals: an honest from-scratch answer has no use for them.
EVASIVE_MODULES = {"importlib", "imp", "runpy", "pkgutil", "zipimport", "ctypes", "gc", "inspect", "marshal",
                   "__main__", "cv3d_learner", "cv3d_sandbox", "builtins", "code", "codeop"}
EVASIVE_CALLS = {"exec", "eval", "compile", "__import__", "globals", "vars", "breakpoint"}
EVASIVE_ATTRIBUTES = {"meta_path", "path_hooks", "path_importer_cache", "modules", "_getframe", "__wrapped_real__",
                      "__wrapped__", "_real", "__loader__", "__spec__", "__globals__", "__builtins__", "__subclasses__",
                      "__code__", "f_back", "f_globals", "f_locals", "gi_frame", "tb_frame", "__closure__"}


def _bound_imports(tree: ast.Module) -> dict[str, str]:
    """Top-level name -> the module (or module.attribute) an import binds it to."""
    bound = {}
    for node in tree.body:
        if isinstance(node, ast.Import):
            for a in node.names:
                bound[a.asname or a.name.split(".")[0]] = a.name if a.asname else a.name.split(".")[0]
        elif isinstance(node, ast.ImportFrom) and node.module and not node.level:
            for a in node.names:
                bound[a.asname or a.name] = f"{node.module}.{a.name}"
    return bound


def reachable(tree: ast.Module, name: str) -> list[ast.AST]:
    """The top-level definitions the exercise's code runs: `name` and what it refers to, transitively."""
    defs = {n.name: n for n in tree.body if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef))}
    constants = {t.id: n for n in tree.body if isinstance(n, (ast.Assign, ast.AnnAssign))
                 for t in (n.targets if isinstance(n, ast.Assign) else [n.target]) if isinstance(t, ast.Name)}
    seen, todo, nodes = set(), [name], []
    while todo:
        current = todo.pop()
        if current in seen:
            continue
        seen.add(current)
        node = defs.get(current) or constants.get(current)
        if node is None:
            continue
        nodes.append(node)
        todo += [n.id for n in ast.walk(node) if isinstance(n, ast.Name)]
    return nodes


def _blocked(module: str, blocked: tuple[str, ...]) -> bool:
    top = module.split(".")[0]
    return top in blocked or top in EVASIVE_MODULES


def findings(source: str, name: str, refused: tuple[str, ...], allowed: tuple[str, ...] = ()) -> list[str]:
    """What the code behind the learner's `name` uses that graded work may not (empty: nothing found).
    refused: the libraries this exercise may not use; allowed: course packages let in (the test suite
    grading `solutions` with CV3D_GRADE_REFERENCE)."""
    refused = tuple(refused) + tuple(m for m in COURSE if m not in allowed)
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return []
    bound = _bound_imports(tree)
    found: list[str] = []
    if name in bound and _blocked(bound[name], refused):
        found.append(f"`{name}` is imported from {bound[name]}")
    for node in reachable(tree, name):
        where = getattr(node, "name", name)
        bases = {id(n.value): f"{bound[n.value.id]}.{n.attr}" for n in ast.walk(node) if isinstance(n, ast.Attribute)
                 and isinstance(n.value, ast.Name) and n.value.id in bound and _blocked(bound[n.value.id], refused)}
        for n in ast.walk(node):
            if id(n) in bases:                 # cv2.projectPoints: name what it calls, not only the module
                found.append(f"`{where}` uses {bases[id(n)]}")
                continue
            if isinstance(n, ast.Import):
                found += [f"`{where}` imports {a.name}" for a in n.names if _blocked(a.name, refused)]
            elif isinstance(n, ast.ImportFrom) and _blocked(n.module or "", refused):
                found.append(f"`{where}` imports from {n.module}")
            elif isinstance(n, ast.Name) and isinstance(n.ctx, ast.Load):
                if n.id in bound and _blocked(bound[n.id], refused):
                    found.append(f"`{where}` uses {n.id} ({bound[n.id]})")
                elif n.id in EVASIVE_CALLS:
                    found.append(f"`{where}` calls {n.id}")
            elif isinstance(n, ast.Attribute) and (n.attr in EVASIVE_ATTRIBUTES or n.attr == "path"
                                                   and isinstance(n.value, ast.Name) and n.value.id == "sys"):
                found.append(f"`{where}` reaches .{n.attr}")
            elif isinstance(n, ast.Constant) and isinstance(n.value, str) and _names_course(n.value, refused):
                found.append(f"`{where}` names {n.value!r}")
    return list(dict.fromkeys(found))


def _names_course(text: str, refused: tuple[str, ...]) -> bool:
    """A string that is a blocked module's dotted name (for importlib) or a path into one (to read it by
    hand); prose that mentions one (a docstring citing cv2.pyrDown) is not."""
    blocked = "|".join(re.escape(m) for m in refused)
    return bool(re.fullmatch(rf"\s*(?:{blocked})(?:\.\w+)*\s*", text)
                or re.search(rf"(?:^|[/\\])(?:{blocked})(?:[/\\]|$)", text))
