"""Worker process of `python -m graders check`: loads extracted learner code and grades exercises.

    python -m graders.worker SOURCE.py RESULTS.jsonl --ids 1.5,1.6 --seed 123

Writes one JSON line per event to RESULTS.jsonl (never to stdout, which the learner's prints may
fill): {"start": id} before an exercise, then {"result": {...}}. The parent kills this process if
an exercise overruns and starts a new worker for the exercises that remain.
"""
from __future__ import annotations

import argparse
import json
import os
import sys

os.environ.setdefault("MPLBACKEND", "Agg")  # a learner's plt.show() must not block

from .engine import get, grade  # noqa: E402
from .report import ExerciseResult  # noqa: E402
from .sandbox import safe_call  # noqa: E402

LOAD_TIMEOUT = 60.0  # seconds for the learner's imports and definitions to run


def load(source: str) -> tuple[dict, str]:
    """Run the learner's extracted definitions; returns (namespace, problem or '')."""
    namespace: dict = {"__name__": "learner"}
    outcome = safe_call(lambda: exec(compile(source, "<your notebook>", "exec"), namespace),
                        timeout=LOAD_TIMEOUT)
    if outcome.kind != "ok":
        return namespace, f"your code failed to load: {outcome.error}\n{outcome.traceback}".rstrip()
    return namespace, ""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("source")
    ap.add_argument("results")
    ap.add_argument("--ids", required=True)
    ap.add_argument("--seed", type=int, default=None)
    args = ap.parse_args(argv)
    with open(args.source, encoding="utf-8") as f:
        source = f.read()
    namespace, problem = load(source)
    with open(args.results, "a", encoding="utf-8", buffering=1) as out:
        for exercise_id in args.ids.split(","):
            out.write(json.dumps({"start": exercise_id}) + "\n")
            ex = get(exercise_id)
            if problem:
                result = ExerciseResult(id=ex.id, title=ex.title, name=ex.name, kind=ex.kind,
                                        max_score=ex.points, seed=args.seed or 0, message=problem)
            elif ex.name not in namespace:
                result = ExerciseResult(id=ex.id, title=ex.title, name=ex.name, kind=ex.kind,
                                        max_score=ex.points, seed=args.seed or 0, status="not_attempted",
                                        message=f"no top-level `{ex.name}` found: not attempted")
            else:
                result = grade(ex, namespace[ex.name], seed=args.seed)
            out.write(json.dumps({"result": result.to_dict()}) + "\n")
    sys.stdout.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
