"""Chapter 6's CONCEPT (6.1-6.6) and DESIGN (6.22-6.25) answers."""
from __future__ import annotations

__all__: list[str] = []
