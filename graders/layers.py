"""The packages of `graders` by role, who they ship to, and what each may import: the one table that
docs/ENGINE.md (its "Packages by role" section: `python -m graders.layers` prints it) and
tests/core/test_layers.py (no import cycle, no import a row does not allow) read.

A module's row is the first folder under `graders/` (`graders/core/engine.py` is in `core`); the chapter
packages `graders/chNN_<stem>/` share the row `chapters`, and the files directly in `graders/` the row `entry`.
"""
from __future__ import annotations

from typing import NamedTuple


class Layer(NamedTuple):
    name: str
    may_import: tuple[str, ...]   # other rows this row's modules may import (its own row always)
    ships_to: str                 # who gets it: learners (the student release) or instructors only
    runs_learner_code: bool       # whether learner code runs in (or is started by) this row
    role: str


LAYERS: tuple[Layer, ...] = (
    Layer("kit", (), "learners", False,
          "shared vision helpers for the judges: geometry, synthetic scenes and the corridor drive, datasets, "
          "3D views, torch threads"),
    Layer("core", ("kit",), "learners", True,
          "the engine: an exercise as data, one attempt run safely in-process (`sandbox`), output checks, "
          "metrics, results, the chapter table"),
    Layer("oracles", ("kit",), "learners", False,
          "stand-ins and oracles that several chapters share (OpenCV, pycolmap, scipy)"),
    Layer("chapters", ("core", "kit", "oracles"), "learners", False,
          "one package per chapter: specs, hidden cases, oracles, hints, stand-ins (never another chapter)"),
    Layer("grading", ("core", "kit"), "learners (batch, release, fairness: instructors)", True,
          "the shell grader (`runner`), its workers, graded mode's learner process, batch, release and "
          "Gradescope, fairness sweeps"),
    Layer("study", ("core", "kit", "grading"), "learners", False,
          "progress, drills, cards and the deck, spaced repetition, mock interviews, the course home, `make lab`"),
    Layer("entry", ("kit", "core", "oracles", "chapters", "grading", "study"), "learners", False,
          "`graders/__init__` (check, use, answer_key), `python -m graders` (cli: parse and dispatch), "
          "`python -m graders.datasets`, this table"),
)
BY_NAME = {layer.name: layer for layer in LAYERS}


def layer_of(module: str) -> str:
    """The row of a dotted module name inside graders (`graders.core.engine` -> `core`)."""
    parts = module.split(".")
    if len(parts) < 2 or parts[0] != "graders":
        raise ValueError(f"{module} is not a module of graders")
    head = parts[1]
    if head.startswith("ch") and head[2:4].isdigit():
        return "chapters"
    return head if head in BY_NAME else "entry"


def markdown() -> str:
    """The table as docs/ENGINE.md shows it."""
    rows = ["| package | may import | ships to | runs learner code | role |", "|---|---|---|---|---|"]
    for layer in LAYERS:
        where = "`graders/chNN_<stem>/`" if layer.name == "chapters" else (
            "`graders/*.py`" if layer.name == "entry" else f"`graders/{layer.name}/`")
        rows.append(f"| {where} | {', '.join(layer.may_import) or '—'} | {layer.ships_to} | "
                    f"{'yes' if layer.runs_learner_code else 'no'} | {layer.role} |")
    return "\n".join(rows)


if __name__ == "__main__":
    print(markdown())
