"""Chapter 11's contract data (tests/chapters/test_contract.py): the mutant catalogue. There is no library to back
these exercises (a monitor, a state machine, a z-test on baselines): the independent check is the grader's own
rule, written apart from the reference (the contract's fallback tests)."""
from __future__ import annotations

from mutants.ch11_capstone import MUTANTS  # noqa: F401 (the contract's catalogue)

SEEDS = [0, 1, 2]
LIBRARY: list = []
