"""Chapter 8's geometry CONCEPT (8.1-8.3) and DESIGN (8.24) questions; each answer computed here, never pasted."""
from __future__ import annotations
