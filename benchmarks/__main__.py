"""`python -m benchmarks [NN ...]`: every chapter's benchmark (from the chapter table), side by side
with the library it is compared against, in one run."""
import argparse
import importlib

from graders.core.chapters import READY

ap = argparse.ArgumentParser(prog="python -m benchmarks")
ap.add_argument("chapters", nargs="*", help="chapter numbers, e.g. 1 or 01; default: all")
args = ap.parse_args()
wanted = {int(c) for c in args.chapters}
for ch in READY:
    if not wanted or ch.number in wanted:
        print(f"\n=== {ch.prefix} ===")
        importlib.import_module(ch.benchmark).run()
