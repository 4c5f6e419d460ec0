"""Chapter 10 — large-scale and learned 3D, from scratch: every learner name of the notebook
(instructor release). numpy and scipy (torch for the pointmap alignment) only."""
from __future__ import annotations

# ---- part A
from .questions import (attention_memory, cluster_gpus, merge_verdicts, pairs_10k, scaling_hours,
                        vocab_tree_numbers)
from .debug import choose_pipelines, chunked_poses, fix_components
from .merge import merge_reconstructions
from .retrieval import vocab_tree_retrieve
from .sim3 import sim3_ransac

__all__ = ["attention_memory", "cluster_gpus", "merge_verdicts", "pairs_10k", "scaling_hours",
           "vocab_tree_numbers", "vocab_tree_retrieve", "sim3_ransac", "merge_reconstructions",
           "fix_components", "choose_pipelines", "chunked_poses"]

# ---- part B: add imports and extend __all__ below this line.
from .distributed import run_pipeline  # noqa: E402
from .frontier import focal_from_pointmap  # noqa: E402
from .pointmaps import global_alignment  # noqa: E402
from .questions import pipeline_choices, pointmap_costs  # noqa: E402

__all__ += ["pointmap_costs", "pipeline_choices", "global_alignment", "run_pipeline", "focal_from_pointmap"]
