"""`make lab`: open the course in JupyterLab, for root and non-root users, with or without a browser.

JupyterLab refuses to start as root unless told `--allow-root` (containers and cloud notebooks run as
root), and tries to open a browser that a headless machine does not have. This launcher passes what
the machine needs and prints the address to open:

    python -m graders.study.lab [--port 8888] [--no-browser] [extra jupyter-lab options]
"""
from __future__ import annotations

import argparse
import os
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def has_browser() -> bool:
    """A browser JupyterLab can open: a display (or macOS) and a browser on the PATH."""
    if sys.platform == "darwin":
        return True
    if not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        return False
    return any(shutil.which(b) for b in ("xdg-open", "firefox", "chromium", "google-chrome", "sensible-browser"))


def workspace() -> Path:
    """The learner's own folder of notebooks: $CV3D_WORKSPACE, else `my-notebooks/` in the checkout (ignored by
    git). Lab serves this, never the tracked `notebooks/`, so a learner's edits never collide with `git pull`."""
    return Path(os.environ.get("CV3D_WORKSPACE") or ROOT / "my-notebooks")


def fill_workspace(folder: Path, source: Path = ROOT / "notebooks") -> list[str]:
    """Copy every course notebook that the workspace does not have yet (a learner's copy is never replaced;
    a chapter that arrives with a later `git pull` is added). Returns the names copied."""
    folder.mkdir(parents=True, exist_ok=True)
    copied = []
    for nb in sorted(source.glob("*.ipynb")):
        if not (folder / nb.name).exists():
            shutil.copy2(nb, folder / nb.name)
            copied.append(nb.name)
    return copied


def lab_command(port: int | None, browser: bool, extra: list[str], folder: Path | None = None) -> list[str]:
    cmd = [sys.executable, "-m", "jupyterlab", f"--notebook-dir={folder or workspace()}"]
    if hasattr(os, "geteuid") and os.geteuid() == 0:
        cmd.append("--allow-root")     # containers run as root; JupyterLab refuses it without this flag
    if not browser:
        cmd.append("--no-browser")
    if port:
        cmd.append(f"--port={port}")
    return cmd + extra


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m graders.study.lab")
    ap.add_argument("--port", type=int, default=int(os.environ.get("LAB_PORT", 0)) or None)
    ap.add_argument("--no-browser", action="store_true", help="do not try to open a browser")
    args, extra = ap.parse_known_args(argv)
    browser = has_browser() and not args.no_browser
    folder = workspace()
    copied = fill_workspace(folder)
    print(f"Your notebooks: {folder}" + (f" ({len(copied)} new copies)" if copied else "") + ". The originals in "
          f"{ROOT / 'notebooks'} stay as shipped: `git pull` updates them; to start a chapter afresh, delete its "
          "copy here and run `make lab` again.", flush=True)
    if not browser:
        print("No browser on this machine: open the http://127.0.0.1:… address printed below in yours "
              "(over SSH: ssh -L 8888:127.0.0.1:8888 this-machine).", flush=True)
    os.execv(sys.executable, lab_command(args.port, browser, extra, folder))
    return 0


if __name__ == "__main__":
    sys.exit(main())
