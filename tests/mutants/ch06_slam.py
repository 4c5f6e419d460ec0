"""Chapter 6 mutant catalogue: realistic wrong implementations, one per known mistake.

Each entry of MUTANTS is (exercise id, short name, function, hint fragment or None). The grader must
take points off every one of them; where a hint exists for the mistake it must fire. Core's entries
(6.7-6.11, 6.18, 6.19, 6.21, 6.26) come first; front-end appends its own in the marked section.
"""
from __future__ import annotations

MUTANTS: list[tuple] = []

# front-end (6.12–6.17, 6.20)
