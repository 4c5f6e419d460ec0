"""The chapter table is the only chapter map: every ready chapter's files exist under its one stem,
and the README lists exactly the table's chapters."""
from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from graders.core.chapters import CHAPTERS, READY, by_number, readme_table

ROOT = Path(__file__).resolve().parents[2]


def test_readme_chapter_list_is_the_table():
    assert readme_table() in (ROOT / "README.md").read_text(), "run `python -m graders.core.chapters` and paste it"


@pytest.mark.parametrize("ch", READY, ids=lambda c: c.prefix)
def test_every_file_of_a_chapter_uses_its_stem(ch):
    for rel in (ch.notebook, f"graders/{ch.prefix}/__init__.py", f"solutions/{ch.prefix}/__init__.py",
                f"tests/mutants/{ch.prefix}.py", f"tests/mutants/{ch.prefix}_contract.py",
                f"tests/chapters/test_{ch.prefix}.py", f"benchmarks/{ch.prefix}.py"):
        assert (ROOT / rel).exists() or (ROOT / rel.removesuffix(".py") / "__init__.py").exists(), rel  # or a package
    importlib.import_module(ch.grader)
    importlib.import_module(ch.solutions)


def test_no_stray_chapter_files():
    stems = {c.prefix for c in CHAPTERS}
    found = {p.stem if p.is_file() else p.name for d in ("graders", "solutions", "benchmarks", "tests/mutants")
             for p in (ROOT / d).iterdir() if p.name.startswith("ch") and p.name[2:4].isdigit()}
    # A chapter's mutants may be split by part: tests/mutants/chNN_<stem>_<part>.py, like its test files.
    stray = {f for f in found if not any(f == s or f.startswith(s + "_") for s in stems)}
    assert not stray, stray
    # Every ready chapter has its notebook; a planned chapter may have one in progress (not run by the tests).
    # notebooks/00_start_here.ipynb is the course home (graders/study/home.py), not a chapter
    notebooks = {p.name for p in (ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb")} - {"00_start_here.ipynb"}
    assert {c.notebook.split("/")[1] for c in READY} <= notebooks <= {c.notebook.split("/")[1] for c in CHAPTERS}


def test_by_number_accepts_the_usual_spellings():
    assert by_number("04") is by_number(4) is by_number("4")
    with pytest.raises(KeyError, match="chapters: 1, 2"):
        by_number(99)
