"""Notebook housekeeping: `python -m tools.notebook_tools strip NOTEBOOK...` removes outputs and
execution counts in place, so notebooks are stored clean (tests/chapters/test_notebooks.py checks it)."""
from __future__ import annotations

import sys

import nbformat


def strip(path: str) -> bool:
    """Remove outputs and execution counts from one notebook; True if it changed."""
    nb = nbformat.read(path, as_version=4)
    changed = False
    for cell in nb.cells:
        if cell.cell_type == "code" and (cell.outputs or cell.execution_count is not None):
            cell.outputs, cell.execution_count, changed = [], None, True
        if cell.get("metadata", {}).pop("execution", None) is not None:
            changed = True
    if changed:
        nbformat.write(nb, path)
    return changed


if __name__ == "__main__":
    if len(sys.argv) < 3 or sys.argv[1] != "strip":
        sys.exit("usage: python -m tools.notebook_tools strip NOTEBOOK.ipynb...")
    for p in sys.argv[2:]:
        print(("stripped " if strip(p) else "clean    ") + p)
