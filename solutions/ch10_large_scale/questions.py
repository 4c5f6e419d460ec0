"""Chapter 10's answers to the CONCEPT (10.1-10.5) and DESIGN (10.14-10.16) questions."""
from __future__ import annotations

import numpy as np

_H = 0.030 / 3600                                   # hours per matched pair at 30 ms
pairs_10k = [10_000 * 9_999 / 2, 10_000 * 9_999 / 2 * _H, 10_000 * 50, 10_000 * 50 * _H]
vocab_tree_numbers = [10 ** 6, 10 * 6, 10 ** 6, np.log(1e6 / 100)]
merge_verdicts = ["safe", "fragile", "impossible", "impossible"]
scaling_hours = [100 * 99 / 2 * _H, 1000 * 999 / 2 * _H, 10_000 * 50 * _H, 100_000 * 30 * _H, 1_000_000 * 20 * _H]
_gpu_h = 1e6 / 100 / 3600 + 1e6 * 50 * _H
cluster_gpus = [1e6 / 100 / 3600, 1e6 * 50 * _H, np.ceil(_gpu_h / 24), np.ceil(_gpu_h / 168)]
_T = 37 * 37 + 5
attention_memory = [_T, (8 * _T) ** 2 * 16 * 2 / 1e9, (30 * _T) ** 2 * 16 * 2 / 1e9,
                    np.floor(np.sqrt(80e9 / 32) / _T)]

# 10.4: two pointmaps (3 a pixel) and two confidence maps (1 a pixel) per pair at 512 x 384; a complete graph
# of 50 images in both orders; MASt3R-SfM's ~10 retrieved pairs per image; all-pairs scores grow as N^2.
pointmap_costs = [2 * (3 + 1) * 512 * 384, 50 * 49, 50 * 10, (60 / 30) ** 2]
# 10.5: preview / survey / wide-baseline textureless / both needs / no GPU / out-of-domain confidence.
pipeline_choices = ["learned", "classical", "learned", "hybrid", "classical", "classical"]
