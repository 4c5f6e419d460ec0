"""Chapter 6's CONCEPT (6.1-6.6) and DESIGN (6.22-6.25) questions; each answer computed here, never pasted."""
from __future__ import annotations
