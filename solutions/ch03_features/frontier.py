"""Exercise 3.19: a tiny learned patch descriptor (a small CNN, InfoNCE), trained on CPU."""
from __future__ import annotations

import numpy as np


# ============================================================ 3.19 a tiny learned descriptor ====

def train_descriptor(P1: np.ndarray, P2: np.ndarray, steps: int = 40, dim: int = 64, seed: int = 0):
    """Exercise 3.19: train a small CNN patch descriptor with InfoNCE on corresponding patches (homographic adaptation).

    P1, P2: (N, 32, 32) float patches, P2[i] corresponding to P1[i]. Trains for exactly `steps`
    Adam steps on batches of 256 pairs, on one torch thread (a fixed amount of work, so the result
    does not depend on how busy the machine is). Returns describe(P: (K, 32, 32)) -> (K, dim) float32
    numpy, unit rows.
    Net: 3 strided 3x3 convolutions (16, 32, 64 channels, BatchNorm, ReLU) -> 4x4x64 -> linear.
    Loss: cross-entropy of the similarity matrix Z1 Z2^T / 0.1 against the diagonal, both ways.
    """
    import torch
    from torch import nn

    torch.manual_seed(seed)

    def prep(P):  # per-patch zero mean, unit std: the network need not learn brightness invariance
        X = torch.as_tensor(np.asarray(P, np.float32))[:, None]
        X = X - X.mean(dim=(2, 3), keepdim=True)
        return X / (X.std(dim=(2, 3), keepdim=True) + 1e-6)

    net = nn.Sequential(
        nn.Conv2d(1, 16, 3, stride=2, padding=1), nn.BatchNorm2d(16), nn.ReLU(),   # 16 x 16
        nn.Conv2d(16, 32, 3, stride=2, padding=1), nn.BatchNorm2d(32), nn.ReLU(),  # 8 x 8
        nn.Conv2d(32, 64, 3, stride=2, padding=1), nn.BatchNorm2d(64), nn.ReLU(),  # 4 x 4
        nn.Flatten(), nn.Linear(64 * 16, dim))
    X1, X2 = prep(P1), prep(P2)
    opt = torch.optim.Adam(net.parameters(), lr=3e-3)
    batch = 256
    target = torch.arange(batch)
    net.train()
    # One thread: on tensors this small a 2-thread pool spends more time waiting for a busy second
    # core than computing (we measured 200 steps take 9 s to 138 s on 2 threads under load).
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        for _ in range(int(steps)):
            idx = torch.randperm(len(X1))[:batch]
            z1 = nn.functional.normalize(net(X1[idx]), dim=1)
            z2 = nn.functional.normalize(net(X2[idx]), dim=1)
            logits = z1 @ z2.T / 0.1
            t = target[:len(idx)]
            loss = nn.functional.cross_entropy(logits, t) + nn.functional.cross_entropy(logits.T, t)
            opt.zero_grad()
            loss.backward()
            opt.step()
    finally:
        torch.set_num_threads(threads)
    net.eval()

    def describe(P: np.ndarray) -> np.ndarray:
        with torch.no_grad():
            return nn.functional.normalize(net(prep(P)), dim=1).numpy()

    return describe
