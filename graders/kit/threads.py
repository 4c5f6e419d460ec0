"""torch's thread count for one block: small tensors are faster on one thread than on a pool.

Spinning up torch's intra-op pool costs more than the arithmetic of the oracles' small problems, and much
more on a busy 2-core machine (docs/ENGINE.md, "Threads and timing"). Graders, benchmarks and notebooks
run such work inside `with torch_threads(1):`, which restores the previous setting on exit.
"""
from __future__ import annotations

from contextlib import contextmanager
from typing import Iterator


@contextmanager
def torch_threads(n: int = 1) -> Iterator[None]:
    """torch on `n` intra-op threads inside the block; the previous count is restored after, also on error."""
    import torch   # imported here: most graders never need torch
    before = torch.get_num_threads()
    torch.set_num_threads(n)
    try:
        yield
    finally:
        torch.set_num_threads(before)
