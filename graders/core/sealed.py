"""Sealed answers: how the student release checks CONCEPT/DESIGN questions without holding their answers.

The instructor's (and the self-learner's) repository states every answer in the clear. The student
release (graders.grading.release) rewrites each `numeric_question(expected=...)` and
`choice_question(answers=...)` into `sealed("7.1")`, which reads `graders/sealed.json`:

- a choice question keeps, per scenario, sha256(salt | id | index | answer): `choice != sealed[i]` tells
  right from wrong (per scenario, as the full repository does) without the answer being in the files;
- a numeric question keeps the salted hashes of the *bands* around its answer (each entry's bin of width
  `tol`, or of log-width log(1 + tol) for a relative metric) that the tolerance interval touches: a local,
  coarse check (it accepts up to about two tolerances away). Graded mode, run by the instructor with the
  plain answers, is the real judge;
- the model answer (`explanation`) is encrypted under a key derived from the right answer (each accepted
  band combination for a numeric one): it appears once the learner's answer is right.

Nothing here is secret against a determined learner (a local check is an oracle they can query); it keeps
answers out of the files, so copying them takes solving (or brute-forcing) the question, never grepping.
"""
from __future__ import annotations

import base64
import hashlib
import itertools
import json
import math
from pathlib import Path
from typing import Any, Callable, Iterable

import numpy as np

SEALED_FILE = Path(__file__).resolve().parents[1] / "sealed.json"   # graders/sealed.json, in a release only
MAX_COMBOS = 729           # joint band combinations a numeric answer keeps (3 bands x 6 entries); beyond, per entry
LOCKED = ("The model answer is sealed in this edition: it appears here once your answer is right "
          "(and with your graded results).")
_specs: dict[str, dict] | None = None


def digest(*parts: Any) -> str:
    """A salted hash, shortened to 80 bits (a release holds thousands of them)."""
    return hashlib.sha256("|".join(str(p) for p in parts).encode()).hexdigest()[:20]


def _keystream(key: bytes, n: int) -> bytes:
    blocks = (hashlib.sha256(key + i.to_bytes(8, "big")).digest() for i in range(n // 32 + 1))
    return b"".join(blocks)[:n]


def xor(data: bytes, key: bytes) -> bytes:
    return bytes(a ^ b for a, b in zip(data, _keystream(key, len(data))))


def b64(data: bytes) -> str:
    return base64.b64encode(data).decode()


# ---------------------------------------------------------------- bands of a numeric answer

def _unit(x: Any) -> np.ndarray:
    """x scaled to unit norm with its largest entry positive (a vector defined up to scale and sign)."""
    v = np.ravel(np.asarray(x, float))
    v = v / np.linalg.norm(v)
    return v * np.sign(v[np.argmax(np.abs(v))])


def bands(x: Any, metric: str, tol: float) -> list[str]:
    """Each entry's band label: `floor(x / tol)` (absolute metrics; "unit": of x scaled to unit norm, sign
    fixed), `sign:floor(log|x| / log(1 + tol))` (relative), or '0' for an exact zero under a relative metric."""
    flat = _unit(x) if metric == "unit" else np.ravel(np.asarray(x, float))
    if metric == "relative":
        step = math.log1p(tol)
        return ["0" if v == 0 else f"{int(np.sign(v))}:{math.floor(math.log(abs(v)) / step)}" for v in flat]
    width = tol if tol > 0 else 1e-12
    return [str(math.floor(v / width)) for v in flat]


def accepted_bands(expected: Any, metric: str, tol: float) -> list[list[str]]:
    """Per entry, every band the tolerance interval [e - tol, e + tol] (relative: |e|(1 -+ tol)) touches."""
    out = []
    for e in (_unit(expected) if metric == "unit" else np.ravel(np.asarray(expected, float))):
        if metric == "relative" and e == 0:
            out.append(["0"])
        elif metric == "relative":
            step, sign = math.log1p(tol), int(np.sign(e))
            lo, hi = (math.floor(math.log(abs(e) * f) / step) for f in (max(1 - tol, 1e-12), 1 + tol))
            out.append([f"{sign}:{k}" for k in range(lo, hi + 1)])
        else:
            width = tol if tol > 0 else 1e-12
            out.append([str(k) for k in range(math.floor((e - tol) / width), math.floor((e + tol) / width) + 1)])
    return out


# ---------------------------------------------------------------- the release's side

def _load() -> dict[str, dict]:
    global _specs
    if _specs is None:
        _specs = json.loads(SEALED_FILE.read_text()) if SEALED_FILE.exists() else {}
    return _specs


def sealed(exercise_id: str) -> "SealedChoice | SealedNumber":
    """The sealed answer of a question of this release (see the module docstring)."""
    spec = _load().get(exercise_id)
    if spec is None:
        raise KeyError(f"{exercise_id}: no sealed answer in {SEALED_FILE} (a broken student release)")
    return (SealedChoice if spec["type"] == "choice" else SealedNumber)(exercise_id, spec)


def _unwrap(spec: dict, label: str) -> str:
    """The explanation, if `label` (derived from the learner's answer) is one its key was wrapped for."""
    key = hashlib.sha256(f"{spec['salt']}|key|{label}".encode()).digest()
    for wrapped in spec.get("keys", []):
        data_key = xor(base64.b64decode(wrapped), key)
        if hashlib.sha256(data_key).hexdigest()[:16] == spec["check"]:
            return xor(base64.b64decode(spec["explanation"]), data_key).decode("utf-8")
    return LOCKED


class _Token:
    """One scenario's sealed answer: equal to the learner's choice iff their salted hashes match."""

    def __init__(self, owner: "SealedChoice", index: int):
        self.owner, self.index = owner, index

    def __eq__(self, other: object) -> bool:
        choice = str(other).strip().lower()
        return digest(self.owner.spec["salt"], self.owner.id, self.index, choice) == self.owner.spec["hashes"][self.index]

    def __ne__(self, other: object) -> bool:
        return not self.__eq__(other)

    __hash__ = None

    def __repr__(self) -> str:
        return "<sealed>"


class SealedChoice:
    """A choice question's answers as `choice_question` reads them: a sequence with one sealed token per scenario."""

    def __init__(self, exercise_id: str, spec: dict):
        self.id, self.spec = exercise_id, spec
        self.tokens = [_Token(self, i) for i in range(len(spec["hashes"]))]

    def __len__(self) -> int:
        return len(self.tokens)

    def __iter__(self):
        return iter(self.tokens)

    def __getitem__(self, i):
        return self.tokens[i]

    def __repr__(self) -> str:
        return f"<{len(self)} sealed answers>"

    def reveal(self, value: Any) -> str:
        try:
            choices = [str(c).strip().lower() for c in value]
        except TypeError:
            return LOCKED
        return _unwrap(self.spec, "/".join(choices))


class SealedNumber:
    """A numeric question's answer as a set of salted band hashes (see `bands`)."""

    def __init__(self, exercise_id: str, spec: dict):
        self.id, self.spec = exercise_id, spec

    def __repr__(self) -> str:
        return "<sealed answer>"

    def _labels(self, value: Any) -> list[str]:
        return bands(value, self.spec["metric"], self.spec["tol"])

    def outside(self, value: Any) -> float:
        """0 if the answer lies in the accepted bands, else the number of entries outside them (all of
        them when only the joint combination is kept)."""
        labels, salt = self._labels(value), self.spec["salt"]
        if len(labels) != self.spec["size"]:
            return float(self.spec["size"])
        if "joint" in self.spec:
            return 0.0 if digest(salt, self.id, "/".join(labels)) in set(self.spec["joint"]) else float(len(labels))
        return float(sum(digest(salt, self.id, i, b) not in set(h) for i, (b, h) in enumerate(zip(labels, self.spec["entries"]))))

    def reveal(self, value: Any) -> str:
        try:
            return _unwrap(self.spec, "/".join(self._labels(value)))
        except (TypeError, ValueError):
            return LOCKED

    def metric(self, real: Callable[[Any, Any], float], tol: float) -> Callable[[Any, Any], float]:
        """The case's metric: against the sealed answer, the entries outside its bands; against a plain value
        (a `value_hint`'s classic slip), 0 if within the question's tolerance of it, else 1."""
        def measure(out: Any, expected: Any) -> float:
            if isinstance(expected, SealedNumber):
                return expected.outside(out)
            return 0.0 if real(out, expected) <= tol else 1.0
        return measure


# ---------------------------------------------------------------- the build's side (graders.grading.release)

def _wrap_keys(salt: str, text: str, labels: Iterable[str]) -> dict:
    import secrets
    data_key = secrets.token_bytes(32)
    keys = [b64(xor(data_key, hashlib.sha256(f"{salt}|key|{label}".encode()).digest())) for label in labels]
    return {"explanation": b64(xor(text.encode("utf-8"), data_key)), "keys": keys,
            "check": hashlib.sha256(data_key).hexdigest()[:16]}


def seal_choice(exercise_id: str, answers: list[str], explanation: str, salt: str) -> dict:
    answers = [str(a).strip().lower() for a in answers]
    return {"type": "choice", "salt": salt, "hashes": [digest(salt, exercise_id, i, a) for i, a in enumerate(answers)],
            **_wrap_keys(salt, explanation, ["/".join(answers)])}


def seal_number(exercise_id: str, expected: Any, metric: str, tol: float, explanation: str, salt: str) -> dict:
    per_entry = accepted_bands(expected, metric, tol)
    spec = {"type": "numeric", "salt": salt, "metric": metric, "tol": float(tol), "size": len(per_entry)}
    if math.prod(len(b) for b in per_entry) <= MAX_COMBOS:
        combos = ["/".join(c) for c in itertools.product(*per_entry)]
        spec["joint"] = sorted(digest(salt, exercise_id, c) for c in combos)
        spec |= _wrap_keys(salt, explanation, combos)
    else:        # too many combinations: per-entry hashes; the model answer opens for the answer's own bands
        spec["entries"] = [sorted(digest(salt, exercise_id, i, b) for b in bs) for i, bs in enumerate(per_entry)]
        spec |= _wrap_keys(salt, explanation, ["/".join(bands(expected, metric, tol))])
    return spec
