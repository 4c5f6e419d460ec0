"""The deck: every card of the course (the reference tables' cards, then each ready chapter's `CARDS`),
the order to learn new ones in, and an Anki export. Cards themselves and how an answer is judged are
in `graders.study.cards`; the tables they come from in `graders.study.reference`."""
from __future__ import annotations

import html
import importlib
from dataclasses import dataclass

from graders.core.chapters import READY
from graders.study.cards import Card
from graders.study.reference import reference_cards


def deck(chapters: bool = True) -> list[Card]:
    """Every card: the shared reference tables, then each ready chapter's `CARDS` (if it exports any).
    Card ids are unique across the deck (checked here: a duplicate would merge two cards' schedules)."""
    cards = list(reference_cards())
    if chapters:
        for ch in READY:
            try:
                module = importlib.import_module(ch.grader)
            except Exception:   # a chapter that does not import must not take the deck down
                continue
            cards += list(getattr(module, "CARDS", ()))
    ids = [c.id for c in cards]
    dupes = sorted({i for i in ids if ids.count(i) > 1})
    if dupes:
        raise ValueError(f"duplicate card ids: {', '.join(dupes)}")
    return cards


def study_order(cards: list[Card]) -> list[Card]:
    """New cards in the order to learn them: one from each table in turn (a day's new cards are varied)."""
    groups: dict[str, list[Card]] = {}
    for c in cards:
        groups.setdefault(c.table or c.id, []).append(c)
    out, queues = [], list(groups.values())
    while queues:
        out += [q.pop(0) for q in queues]
        queues = [q for q in queues if q]
    return out


# ------------------------------------------------------------------ Anki

ANKI_DECK_ID = 1_719_301_903        # fixed: re-importing an export updates the same deck in Anki
ANKI_MODEL_ID = 1_719_301_904


# genanki 0.13.1 writes every card as new (genanki/card.py: type 0, queue 0, ivl 0, reps 0) and has no API
# for Anki's review log (the `revlog` table is created empty): an export cannot carry the learner's history.
NO_HISTORY = ("review history not included: genanki 0.13.1 writes every card as new and cannot write Anki's "
              "review log; your reviews and schedule stay in the progress file (python -m graders drill today)")


@dataclass(frozen=True)
class DrillNote:
    """A CODE drill as an Anki note: the problem on the front, how to solve and check it timed on the back."""
    id: str                      # the exercise id, e.g. "1.5"
    front: str                   # plain text: title, difficulty, target time, the statement
    back: str                    # plain text: the commands to run
    chapter: int


def export_anki(path: str, cards: list[Card] | None = None, drills: list[DrillNote] = ()) -> str:
    """Write the cards and the drills as an Anki package (.apkg, read by Anki and by genanki's own reader).
    Every note is new in Anki: see NO_HISTORY."""
    import genanki
    cards = deck() if cards is None else cards
    model = genanki.Model(ANKI_MODEL_ID, "cv3d-course reference card",
                          fields=[{"name": "Id"}, {"name": "Front"}, {"name": "Back"}, {"name": "Source"}],
                          templates=[{"name": "Card 1", "qfmt": "{{Front}}",
                                      "afmt": "{{FrontSide}}<hr id=answer>{{Back}}<br><small>{{Source}}</small>"}])
    anki = genanki.Deck(ANKI_DECK_ID, "3D computer vision — reference cards")
    esc = html.escape
    for c in cards:
        front = esc(c.prompt) + (f"<br>({esc(', '.join(c.options))})" if c.kind == "choice" else "")
        back = esc(c.back()).replace("\n", "<br>")
        tags = [c.dimension] + ([f"chapter{c.chapter}"] if c.chapter else ["cross-chapter"])
        anki.add_note(genanki.Note(model=model, fields=[esc(c.id), front, back, esc(c.source)], guid=genanki.guid_for(c.id),
                                   tags=tags))
    for d in drills:     # guid "drill:<id>": never the same note as a card
        anki.add_note(genanki.Note(model=model, fields=[esc(f"drill:{d.id}"), esc(d.front).replace("\n", "<br>"),
                                                        esc(d.back).replace("\n", "<br>"), ""],
                                   guid=genanki.guid_for(f"drill:{d.id}"), tags=["drill", f"chapter{d.chapter}"]))
    genanki.Package(anki).write_to_file(path)
    return path
