"""Reference cards: the numbers and tables an interviewer expects you to know, as graded cards.

A `Card` is data: a prompt, an answer and how to grade it —

- `numeric`: a number in `unit`, right within a relative tolerance `tol` (0.02: rounding of a table);
- `magnitude`: an order of magnitude, right when |log10(given / answer)| <= `tol` (0.5: within ~3x),
  for timings and sizes the lesson gives as "~50ms";
- `choice`: one of `options`, matched exactly (case and surrounding spaces ignored);
- `text`: free text, shown beside the model answer and rated by the learner (1 again … 4 easy).

Every card cites a `source` the learner can read (a paper, a book, the course's own table and chapter); its
`origin` records, for the tests only, the line of the course's source notes it was transcribed from. Where that
figure is wrong or dated, `note` says what is right and why (the card's `answer` is the right one). The deck is the course's shared
reference tables (`graders.study.reference`) plus any `CARDS` a chapter's grader package exports: a later
chapter adds cards by adding data to its own package, no code here.
"""
from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

CARD_KINDS = ("numeric", "magnitude", "choice", "text")
RATINGS = {1: "again", 2: "hard", 3: "good", 4: "easy"}     # FSRS's ratings, as the learner types them


@dataclass(frozen=True)
class Card:
    id: str
    prompt: str
    answer: Any                      # a number (in `unit`), a choice, or the model answer text
    kind: str = "text"               # one of CARD_KINDS
    unit: str = ""
    tol: float = 0.0                 # numeric: relative; magnitude: decades (log10)
    options: tuple[str, ...] = ()
    source: str = ""                 # what the learner is shown as the answer's source
    note: str = ""                   # where a quoted figure is wrong or dated: what is right and why
    explain: str = ""                # context shown after answering
    chapter: int | None = None       # None: cross-chapter
    dimension: str = "concept"       # concept | design | code | debug | frontier
    table: str = ""                  # provenance for the tests: the reference table and row it comes from
    row: int = -1
    origin: str = ""                 # provenance for the tests (the course's source notes and line), never shown

    def __post_init__(self):
        assert self.kind in CARD_KINDS, f"{self.id}: kind {self.kind!r}"
        assert self.kind != "choice" or self.answer in self.options, f"{self.id}: answer not among the options"

    def back(self) -> str:
        """The answer side: the answer, the correction of a figure often quoted wrong, context, the source."""
        ans = f"{_fmt(self.answer)} {self.unit}".strip() if self.kind in ("numeric", "magnitude") else str(self.answer)
        parts = [ans]
        if self.note:
            parts.append(f"Correction: {self.note}")
        if self.explain:
            parts.append(self.explain)
        if self.source:
            parts.append(f"Source: {self.source}")
        return "\n".join(parts)


@dataclass
class Verdict:
    correct: bool | None             # None: a text card, to be self-rated
    message: str
    rating: int | None = None        # the FSRS rating this answer implies (None: ask the learner)


def _fmt(x: Any) -> str:
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x)


def _number(response: Any) -> float:
    """A number from what the learner typed: '12', '1.5e3', '4,121', '~50' (a unit after it is ignored)."""
    if isinstance(response, (int, float)):
        return float(response)
    m = re.search(r"[-+]?\d[\d,]*\.?\d*(?:[eE][-+]?\d+)?", str(response))
    if not m:
        raise ValueError(f"no number in {response!r}")
    return float(m.group(0).replace(",", ""))


def grade(card: Card, response: Any) -> Verdict:
    """Grade a response to a card. Never raises: an unreadable response is a wrong answer."""
    if card.kind == "text":
        return Verdict(None, f"Model answer:\n{card.back()}\nRate yourself: 1 again, 2 hard, 3 good, 4 easy.")
    if card.kind == "choice":
        ok = str(response).strip().lower() == str(card.answer).strip().lower()
        return Verdict(ok, ("right. " if ok else f"no: {card.answer}. ") + card.back(), 3 if ok else 1)
    try:
        given = _number(response)
    except ValueError as exc:
        return Verdict(False, f"{exc}. Answer: {card.back()}", 1)
    if card.kind == "numeric":
        err = abs(given - card.answer) / max(abs(card.answer), 1e-12)
        ok = err <= card.tol
        close = err <= 3 * card.tol
    else:
        if given <= 0:
            return Verdict(False, f"an order of magnitude is positive. Answer: {card.back()}", 1)
        err = abs(math.log10(given / card.answer))
        ok, close = err <= card.tol, err <= 2 * card.tol
    if not ok:      # a wrong number was not recalled, however close: never hard/good/easy
        near = "close, but outside the tolerance: " if close else ""
        return Verdict(False, f"no ({_fmt(given)}; {near}rated 1 again). Answer: {card.back()}", 1)
    return Verdict(True, f"right. Answer: {card.back()}", 4 if err <= card.tol / 4 else 3)
