"""Chapter 8's geometry CONCEPT (8.1-8.3) and DESIGN (8.24) answers."""
from __future__ import annotations

__all__: list[str] = []
