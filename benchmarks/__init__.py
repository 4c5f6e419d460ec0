"""Benchmarks: the reference solutions against OpenCV/pycolmap/scipy, measured side by side in one
run. `python -m benchmarks [chapter ...]` runs every `chNN_*.py` module's `run()`."""
