"""Chapter 7 mutant catalogue: realistic wrong implementations, one per known mistake.

Each entry of MUTANTS is (exercise id, short name, function, hint fragment or None). The grader must take points
off every one; where a hint exists for the mistake it must fire. `core` holds 7.5-7.16, `points` 7.17-7.19,
`field` the field DEBUG fixes 7.21-7.22; the mutants are importable by name from here.
"""
from __future__ import annotations

from . import core, field, points
from .core import *  # noqa: F401,F403 (tests import single mutants by name)
from .field import *  # noqa: F401,F403
from .points import *  # noqa: F401,F403

MUTANTS: list[tuple] = core.MUTANTS + points.MUTANTS + field.MUTANTS
