"""The course figure style (graders/kit/style.py) is the one every chapter applies, and nothing undoes it:
no chapter sets its own dpi, and no figure calls tight_layout (under constrained layout it warns on stderr)."""
from __future__ import annotations

import json
import re
from pathlib import Path

from graders.kit.style import COURSE_STYLE, use_course_style

ROOT = Path(__file__).resolve().parents[2]
CHAPTERS = sorted(p for p in (ROOT / "notebooks").glob("[0-9][0-9]_*.ipynb") if not p.name.startswith("00_"))


def _code(path: Path) -> list[str]:
    return ["".join(c["source"]) for c in json.loads(path.read_text())["cells"] if c["cell_type"] == "code"]


def test_the_style_is_readable_at_100_percent():
    assert COURSE_STYLE["figure.dpi"] >= 100 and COURSE_STYLE["font.size"] >= 10
    assert COURSE_STYLE["figure.constrained_layout.use"] is True
    assert min(v for k, v in COURSE_STYLE.items() if k.endswith("size")) >= 9


def test_use_course_style_sets_matplotlib(monkeypatch):
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    with plt.rc_context():
        assert use_course_style() is None          # a set-up cell ending with the call prints nothing
        assert all(plt.rcParams[k] == v for k, v in COURSE_STYLE.items())


def test_every_chapter_applies_it_and_nothing_overrides_it():
    assert len(CHAPTERS) >= 11
    for path in CHAPTERS:
        cells = _code(path)
        assert "use_course_style()" in cells[0], f"{path.name}: the setup cell does not apply the course style"
        for src in cells:
            assert "figure.dpi" not in src, f"{path.name}: sets its own dpi"
            assert not re.search(r"\.tight_layout\(", src), f"{path.name}: tight_layout warns under the style"
    for py in (ROOT / "graders").rglob("*.py"):
        text = py.read_text()
        assert not re.search(r"\.tight_layout\(", text), f"{py}: tight_layout warns under the course style"
        if "subplots_adjust(" in text:
            assert 'layout="none"' in text, f"{py}: subplots_adjust needs a figure made with layout='none'"
