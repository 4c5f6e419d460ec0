"""Graded mode's check for copied stand-ins: a learner function that is one of the course's own stand-ins,
whatever its names.

The student release ships the grader's own implementations that its local checks and demos need
(`standins.KEPT`): graded mode refuses *calling* them (they are not importable in the learner's process),
and this check refuses *copying* them. `copied(source, name, chapters)` compares every function the
learner's `name` runs (itself and the top-level functions it refers to, transitively: static_check's
`reachable`) with every stand-in function of those chapters (`standins.solution_code`), each reduced to
its `shape`: the body's AST without docstring, every identifier replaced by its order of first use, so
renaming variables, arguments or helpers, re-indenting or re-commenting does not hide a copy; attribute
names (`.cumsum`, `.T`) and constants stay. Only functions of at least `MIN_NODES` AST nodes are compared:
a short body (`return K @ X`) is what anyone writes.

It is evidence of copying, not proof of its absence: a copy whose statements are reordered or rewritten
passes it, as a copy passes any plagiarism check that is not a person reading the code. A from-scratch
answer is not refused: tests/grading/test_copies.py holds every function of the course's reference
solutions (written apart from the graders) to no match.
"""
from __future__ import annotations

import ast
import copy
from functools import lru_cache

from graders.core import engine
from graders.core.chapters import by_number
from graders.grading import standins
from graders.grading.static_check import reachable

MIN_NODES = 40        # AST nodes in a body; the smallest stand-in function compared is well above (see the test)


def _count(node: ast.AST) -> int:
    return sum(1 for _ in ast.walk(node))


class _Canonical(ast.NodeTransformer):
    """Every identifier (names, arguments, nested function names) -> v0, v1, ... in order of first use."""

    def __init__(self):
        self.names: dict[str, str] = {}

    def _id(self, name: str) -> str:
        return self.names.setdefault(name, f"v{len(self.names)}")

    def visit_Name(self, node: ast.Name) -> ast.Name:
        return ast.copy_location(ast.Name(self._id(node.id), node.ctx), node)

    def visit_arg(self, node: ast.arg) -> ast.arg:
        return ast.copy_location(ast.arg(self._id(node.arg)), node)       # annotations dropped

    def visit_FunctionDef(self, node: ast.FunctionDef) -> ast.FunctionDef:
        node.name = self._id(node.name)
        node.returns, node.decorator_list = None, []
        return self.generic_visit(node)

    visit_AsyncFunctionDef = visit_FunctionDef


def shape(node: ast.FunctionDef | ast.AsyncFunctionDef) -> str | None:
    """node's arguments and body (docstring dropped) with identifiers numbered in order of first use; None if
    the body has fewer than MIN_NODES nodes."""
    body = node.body[1:] if ast.get_docstring(node) else node.body
    if sum(_count(stmt) for stmt in body) < MIN_NODES:
        return None
    fn = copy.deepcopy(ast.FunctionDef("f", node.args, body, [], None, None, lineno=1, col_offset=0))
    return ast.unparse(ast.fix_missing_locations(_Canonical().visit(fn)))   # keyword names (axis=1) stay: the API's


@lru_cache(maxsize=None)
def standin_shapes(chapter: int) -> dict[str, tuple[str, str]]:
    """shape -> (exercise id, qualified name) of every stand-in function of the chapter that is a solution."""
    out = {}
    for ex in engine.chapter(by_number(chapter).key):
        for fn in standins.solution_code(ex):
            node = standins.def_node(fn)
            key = shape(node) if node is not None else None
            if key:
                out.setdefault(key, (ex.id, f"{fn.__module__}.{fn.__qualname__}"))
    return out


def copied(source: str, name: str, chapters: tuple[int, ...]) -> list[str]:
    """What the code behind the learner's `name` copies from the stand-ins of these chapters (empty: nothing)."""
    try:
        tree = ast.parse(source)
    except SyntaxError:
        return []
    found = []
    for node in reachable(tree, name):
        if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
            continue
        key = shape(node)
        for chapter in chapters if key else ():
            if key in (shapes := standin_shapes(chapter)):
                ex_id, qualname = shapes[key]
                found.append(f"`{node.name}` is the course's stand-in `{qualname}` (exercise {ex_id}) renamed")
    return list(dict.fromkeys(found))
