import argparse
import importlib
import pkgutil

import benchmarks

ap = argparse.ArgumentParser(prog="python -m benchmarks")
ap.add_argument("chapters", nargs="*", help="e.g. 01; default: all")
args = ap.parse_args()
for info in sorted(pkgutil.iter_modules(benchmarks.__path__), key=lambda m: m.name):
    if info.name.startswith("ch") and (not args.chapters or info.name[2:4] in args.chapters):
        print(f"\n=== {info.name} ===")
        importlib.import_module(f"benchmarks.{info.name}").run()
