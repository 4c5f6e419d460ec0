"""The protocol between the engine and a learner's function that runs in another process (graded mode).

The engine judges a plain function and a remote one the same way; a remote one (graders.grading.isolation's
`RemoteFunction`) also reports, per case, what the learner's side printed, which inputs it mutated, and
whether graded mode's rules refuse the case (a library call in a from-scratch exercise, a course stand-in).
The rules live with the grading package (graders.grading.policy); the engine only applies the verdict.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Protocol, runtime_checkable


@dataclass
class CaseReport:
    stdout: str = ""
    mutated: list[str] = field(default_factory=list)
    refusal: str = ""          # why graded mode gives this case nothing ('' if it does not refuse it)


@runtime_checkable
class RemoteAttempt(Protocol):
    def begin_case(self, timeout: float) -> None:
        """Every call the coming case makes shares one time limit of `timeout` seconds."""

    def end_case(self, exercise: Any) -> CaseReport:
        """What the case's calls printed and mutated, and graded mode's verdict on what they used."""
