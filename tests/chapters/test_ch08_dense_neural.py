"""Chapter 8 graders, neural half (8.4-8.7, 8.12-8.16, 8.18-8.23, 8.25): the reference passes with full
marks, the stand-in passes, every mutant loses points with its hint named, value hints stay quiet on the
answer. Seeds are fixed so a failure is reproducible; the graders draw fresh seeds for learners.
"""
from __future__ import annotations

import pytest

import grader_checks as checks
from graders import chapter
from mutants.ch08_dense import MUTANTS
from solutions import ch08_dense as dense

SEEDS = [0, 1, 2]
NEURAL = {"8.4", "8.5", "8.6", "8.7", "8.12", "8.13", "8.14", "8.15", "8.16", "8.18", "8.19", "8.20", "8.21",
          "8.22", "8.23", "8.25"}
EXERCISES = {ex.id: ex for ex in chapter(8) if ex.id in NEURAL}
NEURAL_MUTANTS = [m for m in MUTANTS if m[0] in EXERCISES]


def reference(ex) -> object:
    return checks.reference(ex, (dense,))


@pytest.mark.parametrize("seed", SEEDS)
@pytest.mark.parametrize("exercise_id", list(EXERCISES))
def test_reference_gets_full_marks(exercise_id, seed):
    checks.assert_full_marks(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]), seed)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.fallback is not None])
def test_fallback_passes(exercise_id):
    checks.assert_fallback_passes(EXERCISES[exercise_id])


@pytest.mark.parametrize("exercise_id, name, mutant, hint", NEURAL_MUTANTS, ids=[f"{m[0]}-{m[1]}" for m in NEURAL_MUTANTS])
def test_mutant_is_caught(exercise_id, name, mutant, hint):
    checks.assert_mutant_caught(EXERCISES[exercise_id], name, mutant, hint, SEEDS)


def test_every_code_and_debug_exercise_has_mutants():
    checks.assert_enough_mutants(EXERCISES, NEURAL_MUTANTS)


@pytest.mark.parametrize("exercise_id", [i for i, ex in EXERCISES.items() if ex.value])
def test_value_hints_are_quiet_on_the_answer(exercise_id):
    checks.assert_value_hints_quiet(EXERCISES[exercise_id], reference(EXERCISES[exercise_id]))


def test_volume_render_gradients_match_finite_differences():
    """8.12's reference is differentiable: autograd's d(colour)/d(sigma) equals central differences."""
    import numpy as np
    import torch
    from graders.ch08_dense import ray_batch
    b = ray_batch(np.random.default_rng(0), R=4, S=8)
    sigma = torch.tensor(b["sigma"], requires_grad=True)
    args = (torch.tensor(b["rgb"]), torch.tensor(b["t"]), b["t_far"], torch.tensor(b["u"]))
    dense.volume_render(sigma, *args)[1].sum().backward()
    fd = np.zeros_like(b["sigma"])
    for idx in np.ndindex(*fd.shape):
        for s in (1, -1):
            sg = torch.tensor(b["sigma"]); sg[idx] += s * 1e-6
            fd[idx] += s * float(dense.volume_render(sg, *args)[1].sum()) / 2e-6
    assert np.abs(sigma.grad.numpy() - fd).max() < 1e-6
