"""Seeded training is deterministic across processes, not only within one: two fresh Python
processes training the same network with the same seed and thread count give bit-identical
encoders (on one machine; another CPU or thread count may round differently)."""

from __future__ import annotations

import subprocess
import sys

import pytest

SCRIPT = """
import hashlib, sys, torch
torch.set_num_threads(1)
from safl_bench.check import sample_views
from safl_bench.method_registry import method_class
maps = sample_views("topview", n=24)
net = method_class(sys.argv[1])(width=4, encoder_width=4, code_size=16, hidden=16, batch_size=4,
                                epochs=2, seed=int(sys.argv[2])).fit(maps)
print(hashlib.sha256(net.describe(maps).tobytes()).hexdigest())
"""


def _train_in_a_fresh_process(name: str, seed: int) -> str:
    done = subprocess.run([sys.executable, "-c", SCRIPT, name, str(seed)], capture_output=True,
                          text=True, timeout=300, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    return done.stdout.strip().splitlines()[-1]


@pytest.mark.parametrize("name", ["bigan@1", "stable_afl@1"])  # their small networks
def test_seeded_training_gives_the_same_encoder_in_another_process(name: str) -> None:
    first = _train_in_a_fresh_process(name, 0)
    assert _train_in_a_fresh_process(name, 0) == first
    assert _train_in_a_fresh_process(name, 1) != first  # the seed is what decides
