"""Chapter 10 — large-scale and learned 3D, from scratch: every learner name of the notebook
(instructor release). numpy and scipy (torch for the pointmap alignment) only."""
from __future__ import annotations

# ---- part A
from .questions import (attention_memory, cluster_gpus, merge_verdicts, pairs_10k, scaling_hours,
                        vocab_tree_numbers)
from .debug import fix_components
from .merge import merge_reconstructions
from .retrieval import vocab_tree_retrieve
from .sim3 import sim3_ransac

__all__ = ["attention_memory", "cluster_gpus", "merge_verdicts", "pairs_10k", "scaling_hours",
           "vocab_tree_numbers", "vocab_tree_retrieve", "sim3_ransac", "merge_reconstructions",
           "fix_components"]

# ---- part B: add imports and extend __all__ below this line.
