"""Slow, deterministic oracles kept on disk between processes: chapter 4's photo-set matches and pycolmap's
reconstruction of them take ~26 CPU s, and each process that grades 4.14 or runs notebook 04's photo demo (the
notebook, its check, a test worker) used to redo them.

An entry is found by a digest of everything its value depends on: the function and its arguments, the bytes of
its input files, the source of the modules that compute it and the versions of the libraries they call. A
changed photo, a changed line of the oracle or another OpenCV finds no entry and recomputes. Values are stored
as JSON (arrays tagged with their dtype and shape), never pickled, so reading an entry cannot run code.

Graded mode turns the cache off (`disable`): there the judge's expected values must come from its own
computation, not from a file under the learner's home that the learner's code (in process mode, the same user)
could have written.
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


def disable() -> None:
    """No entry is read or written in this process from now on (graded mode's judge)."""
    global _enabled
    _enabled = False


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
                return decode(json.loads(path.read_text()))
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
