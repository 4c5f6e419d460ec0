"""A mock interview: a few CONCEPT/DESIGN cards, one DEBUG scenario and one CODE drill in a fixed time,
then a report (what was right, time per part, where the time went over).

    python -m graders drill mock [--minutes 45] [--cards 4]

In a notebook: `from graders.study.mock import mock_interview; mock_interview(45)` (it asks with input()).
The report is printed and appended to the progress file as a "mock" event; card ratings and the drill
are recorded as usual, so they join the FSRS schedule.
"""
from __future__ import annotations

import random
import time
from dataclasses import dataclass, field

from graders.study import progress, srs


@dataclass
class MockReport:
    minutes: float
    cards: list[tuple[str, int]] = field(default_factory=list)        # (card id, rating)
    debug: tuple[str, int] | None = None
    drill_id: str = ""
    drill_status: str = "not_attempted"
    drill_score: float = 0.0
    drill_max: float = 0.0
    seconds: dict[str, float] = field(default_factory=dict)            # part -> seconds spent

    def text(self) -> str:
        total = sum(self.seconds.values())
        right = sum(r >= 3 for _, r in self.cards)
        lines = [f"mock interview report — {total / 60:.1f} of {self.minutes:g} min"
                 + ("  (OVER TIME)" if total > 60 * self.minutes else ""),
                 f"  cards: {right}/{len(self.cards)} good or easy ({self.seconds.get('cards', 0) / 60:.1f} min)"]
        lines += [f"    {cid}: {srs_name(r)}" for cid, r in self.cards]
        if self.debug:
            lines.append(f"  debug scenario {self.debug[0]}: {srs_name(self.debug[1])} "
                         f"({self.seconds.get('debug', 0) / 60:.1f} min)")
        lines.append(f"  code drill {self.drill_id}: {self.drill_status}, {self.drill_score:g}/{self.drill_max:g} "
                     f"points ({self.seconds.get('code', 0) / 60:.1f} min)")
        weak = [cid for cid, r in self.cards if r <= 2] + ([self.debug[0]] if self.debug and self.debug[1] <= 2 else [])
        if weak:
            lines.append("  review next: " + ", ".join(weak))
        return "\n".join(lines)


def srs_name(rating: int) -> str:
    from graders.study.cards import RATINGS
    return RATINGS.get(rating, "?")


def _pick_cards(rng: random.Random, n: int):
    from graders.study.deck import deck
    cards = deck()
    quick = [c for c in cards if c.dimension in ("concept", "design")]
    debug = [c for c in cards if c.dimension == "debug"]
    return rng.sample(quick, min(n, len(quick))), rng.choice(debug)


def mock_interview(minutes: float = 45.0, n_cards: int = 4, ask=input, say=print, seed: int | None = None,
                   drill_id: str | None = None) -> MockReport:
    """Run a mock interview: cards, a DEBUG scenario, then a CODE drill checked when the learner says so."""
    from graders.study.drill import ask_card, check_drill, start
    rng = random.Random(seed)
    report = MockReport(minutes)
    cards, scenario = _pick_cards(rng, n_cards)
    say(f"Mock interview: {len(cards)} quick questions, one debugging scenario, one coding task; "
        f"{minutes:g} minutes in all. Type q to skip a question.")
    t = time.monotonic()
    for card in cards:
        rating = ask_card(card, ask, say) or 1
        srs.record_review(card.id, rating, source="mock")
        report.cards.append((card.id, rating))
    report.seconds["cards"] = time.monotonic() - t
    t = time.monotonic()
    say("\nDebugging scenario — talk it through, then compare:")
    rating = ask_card(scenario, ask, say) or 1
    srs.record_review(scenario.id, rating, source="mock")
    report.debug = (scenario.id, rating)
    report.seconds["debug"] = time.monotonic() - t
    t = time.monotonic()
    left = max(1.0, minutes - sum(report.seconds.values()) / 60)
    say(f"\nCoding task ({left:.0f} minutes left):")
    path = start(drill_id, weakest=drill_id is None, seed=seed)
    try:
        ask(f"press Enter when {path.name} is ready to be checked > ")
    except EOFError:
        pass
    result = check_drill(path, quiet=True)
    report.seconds["code"] = time.monotonic() - t
    report.drill_id, report.drill_status = result.id, result.status
    report.drill_score, report.drill_max = result.score, result.max_score
    say(str(result))
    say("\n" + report.text())
    progress.append({"event": "mock", "minutes": minutes, "cards": report.cards, "debug": report.debug,
                     "drill": result.id, "drill_status": result.status, "seconds": report.seconds})
    return report
