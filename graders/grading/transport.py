"""What crosses the pipe between the judge and the learner's process, on the judge's side: replies unpickled
from an allow-list (`loads`), tensors and their gradients brought back (`tensors_back`, `gradients_back`),
callables swapped for handles the learner calls back through (`swap_callables`), and `RemoteError`, a failure
in the learner's process reported as if it had happened here. graders/grading/isolation.py runs the process."""
from __future__ import annotations

import io
import pickle
from typing import Any, Callable

class RemoteError(Exception):
    """The learner's function failed in the learner process: kind (exception | exit | crash), the
    message and the learner's own traceback, reported by the sandbox as if it had happened here."""

    def __init__(self, kind: str, error: str, traceback: str = ""):
        super().__init__(error)
        self.kind, self.error, self.traceback = kind, error, traceback
        self.remote_kind = {"crash": "exit", "garbage": "exception"}.get(kind, kind)   # what graders.core.sandbox reports


# ------------------------------------------------------------------ what may come back

_ALLOWED = {
    ("builtins", n) for n in ("list", "tuple", "dict", "set", "frozenset", "complex", "slice", "range",
                              "bytearray", "object", "bool", "int", "float", "str", "bytes")
} | {
    ("collections", "OrderedDict"), ("copyreg", "_reconstructor"),
    ("numpy", "ndarray"), ("numpy", "dtype"), ("numpy.core.multiarray", "_reconstruct"),
    ("numpy.core.multiarray", "scalar"), ("numpy._core.multiarray", "_reconstruct"),
    ("numpy._core.multiarray", "scalar"), ("numpy._core.numeric", "_frombuffer"),
    ("numpy.core.numeric", "_frombuffer"),
}


class _Unpickler(pickle.Unpickler):
    def find_class(self, module: str, name: str):
        if ((module, name) in _ALLOWED or module.startswith("numpy.dtypes") and name[:1].isupper()
                or module.startswith("scipy.sparse._") and name.endswith(("_matrix", "_array"))):
            return super().find_class(module, name)
        raise pickle.UnpicklingError(f"{module}.{name}")


def loads(data: bytes) -> Any:
    return _Unpickler(io.BytesIO(data)).load()


def tensors_back(value: Any, parent: "RemoteFunction | None" = None) -> Any:
    """Arrays the learner process sent for torch tensors become tensors again; a function it returned
    becomes a handle that calls it there."""
    if isinstance(value, dict) and set(value) == {"__handle__"} and parent is not None:
        return parent.returned(value["__handle__"])
    if isinstance(value, dict) and "__tensor__" in value:
        import torch
        return torch.from_numpy(value["__tensor__"].copy())
    if isinstance(value, (list, tuple)):
        return type(value)(tensors_back(v, parent) for v in value)
    if isinstance(value, dict):
        return {k: tensors_back(v, parent) for k, v in value.items()}
    return value


def _with_gradients(value: Any, grads: list, args: tuple, cotangent: Any = None) -> Any:
    """A tensor equal to the learner's value whose gradients on the judge's own input tensors are the
    learner's: value + L/|L|² Σ <g_i, x_i − x_i.detach()>, with g_i = d(value · L)/dx_i computed on the
    learner's side (L = 1 for a scalar cost). Backward of (out · L).sum() then gives exactly g_i."""
    import torch
    flat = [a for arg in args for a in (arg if isinstance(arg, (list, tuple)) else [arg])]
    leaves = [a for a in flat if isinstance(a, torch.Tensor) and a.requires_grad]
    out = torch.as_tensor(value, dtype=leaves[0].dtype).reshape(value.shape)
    L = torch.ones((), dtype=out.dtype) if cotangent is None else torch.as_tensor(cotangent, dtype=out.dtype)
    first_order = sum((torch.as_tensor(g, dtype=x.dtype) * (x - x.detach())).sum()
                      for x, g in zip(leaves, grads) if g is not None)
    return out + L / (L * L).sum() * first_order


def gradients_back(value: Any, reply: dict, args: tuple, cotangent: Any) -> Any:
    """Put the learner's gradients on the output they belong to: the value itself, or element `at` of it."""
    at = reply.get("grad_at")
    if at is None:
        return _with_gradients(reply["value"]["__tensor__"], reply["grads"], args, cotangent)
    parts = list(value)
    parts[at] = _with_gradients(reply["value"][at]["__tensor__"], reply["grads"], args, cotangent)
    return type(value)(parts)


# ------------------------------------------------------------------ callbacks into the judge

def swap_callables(obj: Any, table: list[Callable]) -> Any:
    """Replace grader callables in the inputs (top level, containers, dict values) by callback handles, and
    grader objects (a pipeline's stages) by handles whose public attributes the learner reads through the
    pipe: the learner's process has no `graders` to rebuild them from."""
    if callable(obj) and not isinstance(obj, type) and not hasattr(obj, "__array__"):
        table.append(obj)
        return {"__callback__": len(table) - 1}
    if type(obj).__module__.split(".")[0] == "graders" and not isinstance(obj, (tuple, list, dict, type)):
        table.append(obj)
        return {"__object__": len(table) - 1}
    if isinstance(obj, tuple):
        return tuple(swap_callables(o, table) for o in obj)
    if isinstance(obj, list):
        return [swap_callables(o, table) for o in obj]
    if isinstance(obj, dict):
        return {k: swap_callables(v, table) for k, v in obj.items()}
    return obj
