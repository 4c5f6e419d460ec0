"""A learner without the data (a fresh clone, or COURSE_DATA at an empty folder): every chapter that grades on a
dataset says so, in the notebook in one `Data:` line with the fetch command (graders.kit.datasets.announce) and in
each check that drops its real-data cases (the exercise's note), never in silence. Static reads and one grade of a
cheap exercise: about a second, no notebook run."""
from __future__ import annotations

import html
import re

import nbformat
import pytest

from graders.core.chapters import READY
from graders.core.engine import chapter, get, grade
from graders.grading.release import chapter_datasets
from graders.kit import datasets
from notebook_stubs import ROOT

ANNOUNCE = re.compile(r"datasets\.announce\(\s*\"(\w+)\"")


@pytest.fixture
def no_data(tmp_path, monkeypatch):
    """COURSE_DATA and the cache both at empty folders."""
    (tmp_path / "data").mkdir()
    monkeypatch.setenv("COURSE_DATA", str(tmp_path / "data"))
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))


def _code(notebook: str) -> str:
    return "\n".join(c.source for c in nbformat.read(ROOT / notebook, as_version=4).cells if c.cell_type == "code")


@pytest.mark.parametrize("ch", READY, ids=lambda c: c.notebook.split("/")[-1])
def test_each_dataset_a_chapter_grades_on_is_declared_and_its_notebook_announces_it(ch):
    graded = set(chapter_datasets(ch.number))           # every dataset name the chapter's grader spells
    declared = {d for ex in chapter(ch.number) for d in ex.datasets}
    assert declared == graded, f"Exercise.datasets {sorted(declared)} vs the grader's datasets {sorted(graded)}"
    code = _code(ch.notebook)
    announced = ANNOUNCE.findall(code)
    assert len(announced) == len(set(announced)), f"a dataset announced twice: {announced}"
    assert set(announced) <= graded, f"announced {announced}, graded on {sorted(graded)}"
    assert bool(announced) == bool(graded), f"graded on {sorted(graded)} but the notebook announces {announced}"
    # the fetch command is the announce line's: a cell skipped without data points back to it, never repeats it
    assert "datasets fetch" not in code and "fetch-data" not in code


@pytest.fixture
def fresh_corners():
    """1.6's real corners are computed once per process (lru_cache): forget them before and after, so this
    test draws without them and later tests draw with them again."""
    from graders.ch01_camera_models.distortion import real_chessboard_corners
    real_chessboard_corners.cache_clear()
    yield
    real_chessboard_corners.cache_clear()


def test_a_check_without_its_data_names_what_it_left_out(no_data, fresh_corners):
    ex = get("1.6")                                     # its real case: the 13 chessboard views
    assert ex.datasets == ("chessboard",)

    def wrong(uv, K, dist):
        return uv                                       # fails every case, cheaply

    r = grade(ex, wrong, seed=1)
    assert r.status == "failed" and all("real" not in c.key for c in r.cases)
    for needed in ("real-data cases were not run", "'chessboard' not found", datasets.fetch_command("chessboard")):
        assert needed in r.message and needed in str(r) and needed in html.unescape(r._repr_html_()), needed

    def untouched(uv, K, dist):
        raise NotImplementedError

    assert "not found" not in grade(ex, untouched, seed=1).message   # "not attempted" stays one line


def test_the_note_is_empty_when_the_data_are_there(monkeypatch):
    monkeypatch.setattr(datasets, "available", lambda name: True)
    assert datasets.missing_note(("sacre_coeur", "sceaux_castle")) == ""
    monkeypatch.setattr(datasets, "available", lambda name: name == "sacre_coeur")
    note = datasets.missing_note(("sacre_coeur", "sceaux_castle"))
    assert "'sceaux_castle' not found" in note and "sacre_coeur" not in note and note.count("\n") == 0
