"""`python -m graders fairness`: does a correct answer ever lose points?

Grades an implementation (by default the chapter's reference package, `solutions.chNN_<stem>`, which
only an instructor checkout has) on fresh random seeds, exercise by exercise, and prints each
exercise's seeds, failures and failing seeds. The solved-notebook test draws fresh seeds on every CI
run, so a reference that fails 1 draw in 700 fails CI at random and grades a learner unfairly; the
target is 0 failures in >= 2,000 seeds for exercises that grade in under 0.1 s and >= 200 for slower
ones (docs/ENGINE.md). Passing is not enough: a case whose error reaches 0.9 of its tolerance on some seed
fails on a rarer one, so the sweep also keeps, per case, the worst error / tolerance ratio it saw (the
margin; 1 is the tolerance) and ends with the exercises sorted by it. A case with no numeric margin (a
zero tolerance, an exception, a rejected output) counts only in the tallies. Read the worst beside the
median: a tolerance built from an oracle's error on the same draw (1.1 x OpenCV's + 0.01 px) or a ratio to
the truth's residual (<= 1.06 x) puts a reference that matches the oracle near 0.9 on every seed, a level,
not a risk; a worst far above the median is the tail that fails one seed in a few hundred.

    python -m graders fairness --chapters 2,4 [--only 4.8] [--seconds-per-exercise 20] [--seeds 2000]
                               [--jobs 2] [--impl my_package] [--json fairness.json]

The graders never import the reference themselves: this command imports the module it is told to
judge, and says so clearly when it is absent (a student release ships without `solutions`).
"""
from __future__ import annotations

import argparse
import importlib
import json
import multiprocessing as mp
import secrets
import statistics
import time
from dataclasses import asdict, dataclass, field

from graders.core.chapters import by_number
from graders.core.engine import Exercise, chapter, get, grade
from graders.core.report import ExerciseResult

FAST_S = 0.1        # an exercise graded faster than this needs >= 2,000 clean seeds, a slower one >= 200
TARGET_FAST, TARGET_SLOW = 2000, 200


@dataclass
class Tally:
    id: str
    name: str
    seeds: int = 0
    failures: int = 0
    failing_seeds: list[int] = field(default_factory=list)
    seconds: float = 0.0
    example: str = ""        # the first failing grade's headline and message
    margins: dict[str, tuple[float, int]] = field(default_factory=dict)   # case key -> (worst error/tol, its seed)
    per_seed: list[float] = field(default_factory=list)   # each grade's largest error/tol (for the median)

    @property
    def per_grade(self) -> float:
        return self.seconds / max(self.seeds, 1)

    @property
    def target(self) -> int:
        return TARGET_FAST if self.per_grade < FAST_S else TARGET_SLOW

    @property
    def worst(self) -> tuple[str, float, int] | None:
        """(case key, error/tol, seed) of the case that came nearest its tolerance; None if none has a margin."""
        if not self.margins:
            return None
        key = max(self.margins, key=lambda k: self.margins[k][0])
        return key, *self.margins[key]

    @property
    def verdict(self) -> str:
        if self.failures:
            return "UNFAIR"
        return "ok" if self.seeds >= self.target else "too few seeds"


def _answer(module_name: str, ex: Exercise):
    module = importlib.import_module(module_name)
    if not hasattr(module, ex.name):
        raise LookupError(f"{module_name} defines no `{ex.name}` (exercise {ex.id})")
    return getattr(module, ex.name)


def _run(args: tuple[str, str, float, int]) -> Tally:
    """One worker: grade exercise `exercise_id` on fresh seeds until `seconds` or `max_seeds` is reached."""
    exercise_id, module_name, seconds, max_seeds = args
    ex = get(exercise_id)
    answer = _answer(module_name, ex)
    tally = Tally(ex.id, ex.name)
    start = time.perf_counter()
    while tally.seeds < max_seeds and (time.perf_counter() - start < seconds or tally.seeds == 0):
        seed = secrets.randbits(32)
        note(tally, grade(ex, answer, seed=seed), ex.points)
        if ex.value:            # a question has no hidden draw: one grade says everything
            break
    tally.seconds = time.perf_counter() - start
    return tally


def note(tally: Tally, result: ExerciseResult, points: float) -> None:
    """Count one grade: its failure if it lost points, and each case's error / tolerance if worse than seen."""
    tally.seeds += 1
    if result.score < points:
        tally.failures += 1
        tally.failing_seeds.append(result.seed)
        if not tally.example:
            bad = next((c for c in result.cases if not c.passed), None)
            tally.example = result.headline() + (
                f" | {bad.name}: {bad.error_text()} vs {bad.tol_text()} {bad.message}".rstrip() if bad else "")
    ratios = []
    for case in result.cases:
        if case.error is not None and case.tol > 0 and case.max_points > 0:   # a row worth 0 cannot cost points
            ratios.append(ratio := case.error / case.tol)
            if ratio >= tally.margins.get(case.key or case.name, (-1.0, 0))[0]:
                tally.margins[case.key or case.name] = (ratio, result.seed)
    if ratios:
        tally.per_seed.append(max(ratios))


def _merge(parts: list[Tally]) -> Tally:
    out = Tally(parts[0].id, parts[0].name)
    for p in parts:
        out.seeds += p.seeds
        out.failures += p.failures
        out.failing_seeds += p.failing_seeds
        out.seconds += p.seconds
        out.example = out.example or p.example
        out.per_seed += p.per_seed
        for key, (ratio, seed) in p.margins.items():
            if ratio >= out.margins.get(key, (-1.0, 0))[0]:
                out.margins[key] = (ratio, seed)
    return out


def sweep(exercise_ids: list[str], module_of: dict[str, str], seconds: float, max_seeds: int,
          jobs: int = 1, report=print) -> list[Tally]:
    """Tally every exercise: `jobs` processes share each exercise's seed budget."""
    tallies = []
    ctx = mp.get_context("fork")
    pool = ctx.Pool(jobs)
    try:
        for exercise_id in exercise_ids:
            ex = get(exercise_id)
            n = 1 if ex.value else jobs
            parts = pool.map(_run, [(exercise_id, module_of[exercise_id], seconds, -(-max_seeds // n))] * n)
            tally = _merge(parts)
            tallies.append(tally)
            report(_row(tally))
    finally:   # close + join, not terminate: a SIGTERM sets off pycolmap's glog handler in the workers
        pool.close()
        pool.join()
    return tallies


def _margin(t: Tally) -> str:
    return "   —" if t.worst is None else f"{t.worst[1]:5.2f}"


def _row(t: Tally) -> str:
    seeds = ", ".join(map(str, t.failing_seeds[:5])) + (" …" if len(t.failing_seeds) > 5 else "")
    line = (f"{t.id:>6} {t.name:<28} {t.seeds:>6} seeds {t.failures:>4} failures  "
            f"{1e3 * t.per_grade:8.1f} ms/grade  worst {_margin(t)}  {t.verdict}")
    return line + (f"\n{'':>8}failing seeds: {seeds}\n{'':>8}{t.example}" if t.failures else "")


def margin_table(tallies: list[Tally]) -> str:
    """The exercises by worst error / tolerance over their seeds, nearest the tolerance first; each with the
    case that came nearest and the seed that drew it (replay with `grade(get(id), answer, seed=...)`)."""
    lines = [f"{'id':>6} {'name':<28} {'worst':>6} {'median':>6}  error/tol; the case that came nearest (its seed)"]
    for t in sorted(tallies, key=lambda t: -1.0 if t.worst is None else t.worst[1], reverse=True):
        if t.worst is None:
            lines.append(f"{t.id:>6} {t.name:<28} {'—':>6} {'—':>6}  no case with a numeric margin")
            continue
        key, ratio, seed = t.worst
        lines.append(f"{t.id:>6} {t.name:<28} {ratio:6.3f} {statistics.median(t.per_seed or [ratio]):6.3f}  {key} ({seed})")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m graders fairness", description=__doc__.split("\n\n")[0])
    ap.add_argument("--chapters", required=True, help="comma-separated chapter numbers, e.g. 1,2")
    ap.add_argument("--only", help="comma-separated exercise ids")
    ap.add_argument("--seconds-per-exercise", type=float, default=10.0)
    ap.add_argument("--seeds", type=int, default=TARGET_FAST, help="stop an exercise after this many seeds")
    ap.add_argument("--jobs", type=int, default=max(1, min(2, mp.cpu_count())))
    ap.add_argument("--impl", help="module to judge instead of the chapter's reference package")
    ap.add_argument("--json", help="write the tallies here")
    args = ap.parse_args(argv)
    ids, module_of = [], {}
    for number in args.chapters.split(","):
        ch = by_number(number)
        module = args.impl or ch.solutions
        try:
            importlib.import_module(module)
        except ImportError as exc:
            print(f"cannot import {module} ({exc}): the fairness sweep needs the implementation to judge "
                  "(the reference solutions ship only in the instructor's checkout)")
            return 2
        for ex in chapter(ch.key):
            if not args.only or ex.id in args.only.split(","):
                ids.append(ex.id)
                module_of[ex.id] = module
    print(f"{'id':>6} {'name':<28} fresh seeds, failures, time per grade "
          f"(target: 0 failures in >= {TARGET_FAST} seeds if < {1e3 * FAST_S:g} ms, else >= {TARGET_SLOW})")
    tallies = sweep(ids, module_of, args.seconds_per_exercise, args.seeds, args.jobs)
    print("\nmargins (error / tolerance; 1 fails; above ~0.6 on a random case, a rarer seed may fail):")
    print(margin_table(tallies))
    unfair = [t.id for t in tallies if t.failures]
    short = [t.id for t in tallies if not t.failures and t.seeds < t.target and not get(t.id).value]
    print(f"\n{len(tallies)} exercises: {len(unfair)} lose points on a correct answer"
          f"{' (' + ', '.join(unfair) + ')' if unfair else ''}; {len(short)} below their seed target"
          f"{' (' + ', '.join(short) + ')' if short else ''}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump([asdict(t) | {"verdict": t.verdict, "worst": t.worst, "per_seed": None} for t in tallies], f, indent=1)
    return 1 if unfair else 0
