"""Spaced repetition of cards and drills with FSRS (the `fsrs` package), from the learner's own record.

Nothing is stored but the progress file (graders.study.progress): a card review is a line
{"event": "review", "item": "card:<id>", "rating": 1-4}; a drill is its attempt line (source "drill"),
rated from its score and time. Each item's FSRS state is rebuilt by replaying its reviews in order
(fuzzing off, so the replay is deterministic), so the schedule can never disagree with the record.

Ratings: 1 again, 2 hard, 3 good, 4 easy. A drill that passes within half its target time is easy,
within its target good, slower hard; a drill that does not pass is again.

Drills are rated once a day: the first graded attempt of a local day is that day's review (a drill is a
test of recall, so checking again after fixing it the same day does not add a review). Cards keep FSRS's
learning steps (1 and 10 minutes: a new fact is asked again in the session); drills have none
(`DRILL_SCHEDULER`), since re-solving a problem minutes later tests short-term memory. With fsrs 6.3.2's
default parameters a first drill rated again or hard is due in 1 day, good in 2 days, easy in 8 days.
"""
from __future__ import annotations

import zlib
from dataclasses import dataclass
from datetime import date, datetime, timezone
from typing import Iterable

from fsrs import Card as FsrsCard
from fsrs import Rating, Scheduler

from graders.study import progress

SCHEDULER = Scheduler(enable_fuzzing=False)
DRILL_SCHEDULER = Scheduler(enable_fuzzing=False, learning_steps=(), relearning_steps=())   # intervals in days
NEW_PER_DAY = 10


def when(t: float) -> datetime:
    return datetime.fromtimestamp(float(t), tz=timezone.utc)


def drill_rating(event: dict) -> int:
    """The FSRS rating of a drill attempt: from its status and its time against the target."""
    if event.get("status") != "passed":
        return 1
    seconds, target = float(event.get("seconds") or 0), 60 * float(event.get("target_minutes") or 0)
    if not target:
        return 3
    return 4 if seconds <= target / 2 else 3 if seconds <= target else 2


def reviews(events: Iterable[dict]) -> list[tuple[str, int, float]]:
    """(item, rating, time) of every card review and of each drill's first attempt of a day, oldest first."""
    out = []
    for e in events:
        try:
            if e.get("event") == "review" and int(e["rating"]) in (1, 2, 3, 4):
                out.append((str(e["item"]), int(e["rating"]), float(e["t"])))
            elif e.get("event") == "attempt" and e.get("source") == "drill" and e.get("status") != "not_attempted":
                out.append((f"drill:{e['id']}", drill_rating(e), float(e["t"])))
        except (KeyError, TypeError, ValueError):   # a line from an older or damaged file: not a review
            continue
    out.sort(key=lambda r: r[2])
    seen: set[tuple[str, date]] = set()     # (drill, local day) already rated
    kept = []
    for item, rating, t in out:
        if item.startswith("drill:"):
            day = (item, when(t).astimezone().date())
            if day in seen:
                continue
            seen.add(day)
        kept.append((item, rating, t))
    return kept


def scheduler(item: str) -> Scheduler:
    """Drills are scheduled in days (no learning steps), cards with FSRS's default minute steps first."""
    return DRILL_SCHEDULER if item.startswith("drill:") else SCHEDULER


def states(events: Iterable[dict]) -> dict[str, FsrsCard]:
    """Each reviewed item's FSRS card after replaying its reviews."""
    cards: dict[str, FsrsCard] = {}
    for item, rating, t in reviews(events):
        if item not in cards:
            cards[item] = FsrsCard(card_id=zlib.crc32(item.encode()), due=when(t))
        cards[item], _ = scheduler(item).review_card(cards[item], Rating(rating), review_datetime=when(t))
    return cards


@dataclass
class Due:
    reviews: list[tuple[str, datetime]]      # (item, when it fell due), most overdue first
    new_cards: list[str]                     # card ids never reviewed, up to today's allowance
    upcoming: list[tuple[str, datetime]]     # the next few that are not due yet


def due(events: list[dict], card_ids: list[str], now: datetime | None = None, new_per_day: int = NEW_PER_DAY) -> Due:
    """What is due at `now`: reviewed items (cards and drills) whose FSRS due date has passed, and new
    cards (in deck order) up to `new_per_day` minus the cards first seen today."""
    now = now or datetime.now(timezone.utc)
    st = states(events)
    overdue = sorted(((i, c.due) for i, c in st.items() if c.due <= now), key=lambda x: x[1])
    later = sorted(((i, c.due) for i, c in st.items() if c.due > now), key=lambda x: x[1])[:5]
    first_seen: dict[str, float] = {}
    for item, _, t in reviews(events):
        first_seen.setdefault(item, t)
    today = now.astimezone().date()
    started_today = sum(1 for i, t in first_seen.items() if i.startswith("card:") and when(t).astimezone().date() == today)
    fresh = [c for c in card_ids if f"card:{c}" not in st][:max(0, new_per_day - started_today)]
    return Due(overdue, fresh, later)


def record_review(card_id: str, rating: int, **extra) -> bool:
    """Append a card review (rating 1-4) to the progress file. Never raises."""
    return progress.append({"event": "review", "item": f"card:{card_id}", "rating": int(rating), **extra})
