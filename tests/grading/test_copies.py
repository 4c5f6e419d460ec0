"""Graded mode refuses a copy of the course's own stand-ins, renamed or not (graders.grading.copies), and never
takes a from-scratch answer for one."""
from __future__ import annotations

import ast
import inspect
import textwrap
from pathlib import Path

import pytest

from graders.core import engine
from graders.core.chapters import READY
from graders.grading import worker
from graders.grading.copies import MIN_NODES, copied, shape, standin_shapes
from graders.ch01_camera_models import fisheye

from grading.test_attacks import HEADER, judge, level  # noqa: F401 (the fixture: both protection levels)

ROOT = Path(__file__).resolve().parents[2]

# The learner's own helpers (what the stand-in calls from the shared kit, written again) and the stand-in 1.8
# gets in self-study, gt_fisheye_unproject, copied with every name changed.
HELPERS = '''
def to_normalised(uv, K):
    return np.linalg.solve(K, np.c_[uv, np.ones(len(uv))].T).T[:, :2]

def distorted_angle(th, D):
    return th * (1 + D[0] * th**2 + D[1] * th**4 + D[2] * th**6 + D[3] * th**8)

def max_angle(D):
    th = np.linspace(0.0, np.pi, 4097)
    rising = np.diff(distorted_angle(th, D)) > 0
    return float(np.pi) if rising.all() else float(th[np.argmin(rising)])
'''
RENAMES = {"gt_fisheye_unproject": "fisheye_unproject", "pixels_to_normalised": "to_normalised",
           "kb_theta_d": "distorted_angle", "lens_max_angle": "max_angle", "uv": "pix", "a": "m", "theta_d": "rd",
           "lo": "left", "hi": "right", "mid": "centre", "below": "under", "theta": "ang", "phi": "az", "D": "dist"}


class _Rename(ast.NodeTransformer):
    def visit_Name(self, node):
        return ast.copy_location(ast.Name(RENAMES.get(node.id, node.id), node.ctx), node)

    def visit_arg(self, node):
        return ast.copy_location(ast.arg(RENAMES.get(node.arg, node.arg), node.annotation), node)

    def visit_FunctionDef(self, node):          # renamed, and its docstring gone
        node.name = RENAMES.get(node.name, node.name)
        node.body = node.body[1:] if ast.get_docstring(node) else node.body
        return self.generic_visit(node)


def renamed_copy() -> str:
    tree = ast.parse(textwrap.dedent(inspect.getsource(fisheye.gt_fisheye_unproject)))
    return HEADER + HELPERS + "\n" + ast.unparse(_Rename().visit(tree)) + "\n"


def test_a_renamed_copy_of_a_stand_in_scores_nothing_in_graded_mode_and_full_marks_in_self_study(level):
    source = renamed_copy()
    assert "gt_fisheye_unproject" not in source and "lens_max_angle" not in source
    refused = judge(source, ["1.8"])["1.8"]
    assert refused.score == 0 and "stand-in" in str(refused) and "gt_fisheye_unproject" in str(refused), str(refused)
    ex = engine.get("1.8")
    own = worker.judge_one(worker._SelfStudy(source), ex, 7)      # the same code is a correct answer
    assert own.score == ex.points, str(own)[:1500]


def test_what_the_learner_writes_around_a_copy_does_not_hide_it():
    source = renamed_copy().replace("    ang = 0.5", "    # a comment\n    ang = 0.5") + "\nx = 1\n"
    assert copied(source, "fisheye_unproject", (1,))
    assert not copied(source.replace("range(60)", "range(61)"), "fisheye_unproject", (1,))   # a constant is content
    assert not copied(source, "fisheye_unproject", (2,))                    # chapter 2 has no such stand-in


def test_no_function_of_the_reference_solutions_is_taken_for_a_copy():
    """The references were written apart from the graders: a from-scratch answer, so none may match."""
    shapes = {}
    for ch in READY:
        shapes.update(standin_shapes(ch.number))
    assert len(shapes) > 100
    compared, matched = 0, []
    for path in sorted((ROOT / "solutions").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)) and (key := shape(node)):
                compared += 1
                if key in shapes:
                    matched.append((path.name, node.name, shapes[key]))
    assert compared > 400 and not matched, matched


@pytest.mark.parametrize("body, compared", [("return K @ X", False), ("return " + " + ".join(["X"] * 30), True)])
def test_short_bodies_are_not_compared(body, compared):
    node = ast.parse(f"def f(K, X):\n    {body}\n").body[0]
    assert (shape(node) is not None) is compared
    assert MIN_NODES > sum(1 for _ in ast.walk(ast.parse("return K @ X").body[0]))
