"""Shared vision helpers for the judges: geometry primitives, synthetic scenes and the corridor drive,
real datasets, 3D views, torch threads. Ships to learners. Imports nothing else of `graders`."""
