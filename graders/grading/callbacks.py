"""Serving the grader's callbacks to the learner's process (graded mode): a grader object a case hands over (10.10's
pipeline stages, a DEBUG exercise's colleague) stays in the judge, and the learner's calls to it come back over the
pipe. Most are served inline, one at a time; an object marked `served_concurrently` is served in threads of its own
(at most MAX_CONCURRENT at once), so the judge can observe calls that overlap in time (10.10: tasks on Dask workers).
`LearnerProcess` (graders.grading.isolation) mixes this in."""
from __future__ import annotations

import os
import threading
import time
from typing import Any, Callable

from graders.core.sandbox import TimeLimitExceeded
from graders.grading.learner import send
from graders.grading.transport import swap_callables, tensors_back

MAX_CONCURRENT = 8      # grader callbacks served at once for one learner process (10.10's stages)


class CallbackServing:
    """The callback half of `LearnerProcess`: it sets `_sending` (a lock on the request pipe and the callback
    table), `_slots` (a BoundedSemaphore(MAX_CONCURRENT)), `req` (non-blocking), `_write_by` (the deadline of its writes: a
    learner that stops reading makes a reply fail with TimeoutError, never blocks the judge), `proc` and `stop()`."""

    def _dispatch_callback(self, request: dict, callbacks: list[Callable], serving: list, deadline: float) -> None:
        """Serve one callback here, or in a thread of its own if its grader object asks to be served concurrently
        (`served_concurrently`: 10.10's stages, whose concurrent calls are what the judge observes); at most
        MAX_CONCURRENT at once, whatever the learner's code sends."""
        try:
            target = _callback_target(request, callbacks)
        except IndexError:
            target = None
        if "attr" in request or not getattr(getattr(target, "__self__", target), "served_concurrently", False):
            self._serve_callback(request, callbacks)
            return
        serving[:] = [t for t in serving if t.is_alive()]
        if not self._slots.acquire(timeout=max(deadline - time.monotonic(), 0.0)):
            raise TimeLimitExceeded("time limit exceeded (the grader's callbacks were never read)")

        def serve() -> None:
            try:
                self._serve_callback(request, callbacks)
            except OSError:       # the learner's process has ended: nobody to reply to
                pass
            finally:
                self._slots.release()
        thread = threading.Thread(target=serve, name="cv3d-callback", daemon=True)
        thread.start()
        serving.append(thread)

    def _join(self, serving: list[threading.Thread], deadline: float) -> None:
        """Every callback served in a thread has replied before the exchange ends (a late reply would land in the
        next request's frames); one still writing past the deadline means the learner stopped reading: its
        process ends (the reply's write then fails) and the next call starts a fresh one."""
        for thread in serving:
            thread.join(max(deadline - time.monotonic(), 0.0) + 1.0)
        if any(t.is_alive() for t in serving):
            try:
                os.killpg(self.proc.pid, 9)      # first: a write blocked on its pipe then fails (EPIPE)
            except (ProcessLookupError, PermissionError, AttributeError):
                pass
            for thread in serving:
                thread.join()
            self.stop()

    def _serve_callback(self, request: dict, callbacks: list[Callable]) -> None:
        try:
            target = _callback_target(request, callbacks)
            if "attr" in request:        # a public attribute of a grader object the case handed over
                if request["attr"].startswith("_"):
                    raise AttributeError(f"{type(target).__name__} has no public attribute {request['attr']!r}")
                value = getattr(target, request["attr"])
            else:
                value = target(*tensors_back(request["args"]), **request["kwargs"])
            reply = {"ok": True, "value": value}
        except Exception as exc:   # the grader's callback failing on the learner's inputs: the learner's error
            reply = {"ok": False, "error": f"{type(exc).__name__}: {exc}",
                     "type": type(exc).__name__ if type(exc).__module__.startswith("graders") else ""}
        with self._sending:      # the callback table and the pipe: one thread at a time
            if reply["ok"]:
                reply["value"] = swap_callables(reply["value"], callbacks)
            send(self.req, dict(reply, op="reply", id=request.get("id")), deadline=self._write_by)


def _callback_target(request: dict, callbacks: list[Callable]) -> Any:
    index = request.get("index")
    if not isinstance(index, int) or not 0 <= index < len(callbacks):
        raise IndexError(f"no grader callback number {index!r}")
    return callbacks[index]
