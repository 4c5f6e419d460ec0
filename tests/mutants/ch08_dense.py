"""Chapter 8 mutant catalogue: realistic wrong implementations, one per known mistake.

Each entry of MUTANTS is (exercise id, short name, function, hint fragment or None). The grader must
take points off every one of them; where a hint exists for the mistake it must fire. Geometry's entries
(8.8-8.11, 8.17) come first; neural appends its own in the marked section.
"""
from __future__ import annotations

MUTANTS: list[tuple] = []

# neural (8.4-8.7, 8.12-8.16, 8.18-8.23, 8.25)
