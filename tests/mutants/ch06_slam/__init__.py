"""Chapter 6 mutant catalogue: realistic wrong implementations, one per known mistake.

Each entry of MUTANTS is (exercise id, short name, function, hint fragment or None). The grader must
take points off every one of them; where a hint exists for the mistake it must fire. One module per part:
`core` (6.7-6.11, 6.18, 6.19, 6.21, 6.26), `frontend` (6.12-6.17, 6.20), `g2o_writer` (6.27).
"""
from __future__ import annotations

from . import core, frontend, g2o_writer

MUTANTS: list[tuple] = core.MUTANTS + frontend.MUTANTS + g2o_writer.MUTANTS
