"""Slow, deterministic oracles kept on disk between processes: chapter 4's photo-set matches and pycolmap's
reconstruction of them take ~26 CPU s, and each process that grades 4.14 or runs notebook 04's photo demo (the
notebook, its check, a test worker) used to redo them.

An entry is found by a digest of everything its value depends on: the function and its arguments, the bytes of
its input files, the source of the modules that compute it and the versions of the libraries they call. A
changed photo, a changed line of the oracle or another OpenCV finds no entry and recomputes. Values are stored
as JSON (arrays tagged with their dtype and shape), never pickled, so reading an entry cannot run code.

Graded mode's judge must not take its expected values from a file the learner's code could have written. Where the
learner's code runs as the judge's own user (process level without root), it turns the cache off (`disable`). Where
every learner process runs as another user (`nobody` at namespace level, a uid of its own at process level as root:
graders.grading.users), it keeps the cache but trusts only what that other user cannot have written (`judge_only`):
a folder and an entry owned by the judge's user and writable by no one else. Such an entry was written by a process
of the judge's user, which runs the course's code, never a learner's in graded mode; a learner's code that did run as
that user (self-study as root) could as well have rewritten graders/ itself, which the judge imports.
"""
from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import json
import os
import tempfile
from pathlib import Path
from types import ModuleType
from typing import Any, Callable, Iterable

import numpy as np

_enabled = True
_judge_only = False


def disable() -> None:
    """No entry is read or written in this process from now on (graded mode's judge, learners as its user)."""
    global _enabled
    _enabled = False


def judge_only() -> None:
    """From now on an entry is read only if it and its folder belong to this process's user and no one else may
    write them (graded mode's judge, whose learners run as another user); `disable` still wins."""
    global _judge_only
    _judge_only = True


def mode() -> str:
    """"on", "judge only" or "off"."""
    return "off" if not _enabled else "judge only" if _judge_only else "on"


def _owned_and_closed(st: os.stat_result) -> bool:
    return st.st_uid == os.geteuid() and not st.st_mode & 0o022


def _closed_way(folder: Path) -> bool:
    """`folder` is this user's and closed to others, and no one else can swap it: every folder above belongs to
    root or this user and is writable by no one else, or is sticky (/tmp: no one renames what is not theirs)."""
    path = os.path.realpath(folder)
    if not _owned_and_closed(os.stat(path)):
        return False
    while path != os.path.dirname(path):
        path = os.path.dirname(path)
        st = os.stat(path)
        if st.st_uid not in (0, os.geteuid()) or (st.st_mode & 0o022 and not st.st_mode & 0o1000):
            return False
    return True


def _read(path: Path) -> Any:
    """The entry's document; in judge-only mode only from an entry and a folder this user alone may write."""
    if not _judge_only:
        return json.loads(path.read_text())
    if not _closed_way(path.parent):
        raise ValueError("a folder others may write")
    fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW)
    with os.fdopen(fd) as f:
        if not _owned_and_closed(os.fstat(fd)):
            raise ValueError("an entry others may have written")
        return json.load(f)


def folder() -> Path:
    """$XDG_CACHE_HOME/cv3d-course/computed (else ~/.cache/...): beside the datasets' download cache."""
    from graders.kit.datasets import cache_dir
    return cache_dir() / "computed"


def _digest_files(h, paths: Iterable[Path]) -> None:
    for p in sorted(Path(p) for p in paths):
        h.update(p.name.encode())
        h.update(hashlib.sha256(p.read_bytes()).digest())


def on_disk(inputs: Callable[..., Iterable[Path]], code: Iterable[ModuleType], libraries: Iterable[str] = ()):
    """Decorate `fn(*args)` (hashable, repr-stable arguments) whose value depends only on its arguments, the files
    `inputs(*args)` lists, the source files of the modules `code` and the versions of `libraries`."""
    def decorate(fn: Callable) -> Callable:
        @functools.wraps(fn)
        def cached(*args):
            if not _enabled:
                return fn(*args)
            h = hashlib.sha256(repr((fn.__module__, fn.__qualname__, args)).encode())
            _digest_files(h, inputs(*args))
            _digest_files(h, (m.__file__ for m in code))
            h.update(repr([importlib.metadata.version(name) for name in libraries]).encode())
            path = folder() / f"{fn.__name__}-{h.hexdigest()[:24]}.json"
            try:
                return decode(_read(path))
            except (OSError, ValueError, KeyError, TypeError):
                pass
            value = fn(*args)
            _write(path, encode(value))
            return value
        return cached
    return decorate


def _write(path: Path, doc: Any) -> None:
    """Atomically (a reader never sees half a file); a cache that cannot be written is no error."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".part-")
        with os.fdopen(fd, "w") as f:
            json.dump(doc, f)
        os.replace(tmp, path)
    except OSError:
        pass


def encode(x: Any) -> Any:
    """A JSON document for `x`: dicts (any hashable keys), lists, tuples, numpy arrays and scalars, None."""
    if isinstance(x, np.ndarray):
        return {"ndarray": [x.dtype.str, list(x.shape), x.ravel().tolist()]}
    if isinstance(x, np.generic):
        return encode(x.item())
    if isinstance(x, dict):
        return {"dict": [[encode(k), encode(v)] for k, v in x.items()]}
    if isinstance(x, tuple):
        return {"tuple": [encode(v) for v in x]}
    if isinstance(x, list):
        return [encode(v) for v in x]
    if x is None or isinstance(x, (bool, int, float, str)):
        return x
    raise TypeError(f"cannot store a {type(x).__name__} on disk")


def decode(doc: Any) -> Any:
    """The value `encode` made `doc` from (floats exactly: JSON keeps their shortest round-trip form)."""
    if isinstance(doc, list):
        return [decode(v) for v in doc]
    if not isinstance(doc, dict):
        return doc
    (tag, body), = doc.items()
    if tag == "ndarray":
        dtype, shape, values = body
        return np.array(values, dtype=np.dtype(dtype)).reshape(shape)
    if tag == "tuple":
        return tuple(decode(v) for v in body)
    if tag == "dict":
        return {_hashable(decode(k)): decode(v) for k, v in body}
    raise KeyError(tag)


def _hashable(key: Any) -> Any:
    return tuple(key) if isinstance(key, list) else key
