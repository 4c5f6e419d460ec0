"""Chapter 10 — large-scale and learned 3D, from scratch: every learner name of the notebook
(instructor release). numpy and scipy (torch for the pointmap alignment) only."""
from __future__ import annotations

# ---- part A
from .questions import (attention_memory, cluster_gpus, merge_verdicts, pairs_10k, scaling_hours,
                        vocab_tree_numbers)

__all__ = ["attention_memory", "cluster_gpus", "merge_verdicts", "pairs_10k", "scaling_hours",
           "vocab_tree_numbers"]

# ---- part B: add imports and extend __all__ below this line.
