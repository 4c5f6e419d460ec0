"""Graded mode's rules on what a learner's code may call, applied to what the learner's process used.

CODE exercises are from scratch: `cv2`, `pycolmap` and `kornia` are refused unless the exercise lists the
library in `Exercise.libraries` (other kinds allow them); the course's own stand-ins and oracles are never an
answer. The engine applies the verdict through `graders.core.attempt.RemoteAttempt.end_case`.
"""
from __future__ import annotations

from typing import Any, Iterable


def refusal(exercise: Any, used: Iterable[str]) -> str:
    """Why graded mode gives a case nothing, from the names the learner's code called ('' if allowed)."""
    used = list(used)
    course = [u for u in used if u.startswith("graders")]
    banned = [u for u in used if not u.startswith("graders") and u.split(".")[0] not in exercise.libraries]
    if course:
        return (f"calls {', '.join(course[:3])}: the course's own stand-ins and oracles are not an "
                "answer in graded work (self-study checks allow them)")
    if banned:
        return (f"calls {', '.join(banned[:3])}: exercise {exercise.id} is from scratch, so graded work "
                f"may not use {', '.join(sorted({b.split('.')[0] for b in banned}))} (self-study checks allow it)")
    return ""
