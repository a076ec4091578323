"""BiGAN: conformance, deterministic seeded training, losses logged."""

from __future__ import annotations

import numpy as np
import pytest

from baselines.bigan import BiGAN
from safl_bench.check import check_method, sample_views

pytestmark = pytest.mark.usefixtures("one_torch_thread")


def tiny(**kw):
    kw.setdefault("epochs", 1)
    return BiGAN(width=4, encoder_width=4, code_size=16, hidden=16, batch_size=4, **kw)


def test_conforms():
    m = check_method(tiny())
    assert m.describe(sample_views("topview", n=2)).shape == (2, 16)


def test_default_code_is_1024_float32():
    d = BiGAN().describe(sample_views("topview", n=2))
    assert d.shape == (2, 1024) and d.dtype == np.float32


def test_training_is_deterministic_for_a_seed_and_logs_losses(tmp_path):
    maps = sample_views("topview", n=16)
    a = tiny(epochs=2).fit(maps, checkpoint_dir=tmp_path)
    b = tiny(epochs=2).fit(maps)
    c = tiny(epochs=2, seed=1).fit(maps)
    np.testing.assert_array_equal(a.describe(maps), b.describe(maps))
    assert not np.array_equal(a.describe(maps), c.describe(maps))
    lines = (tmp_path / "log.jsonl").read_text().splitlines()
    assert len(lines) == 2 and '"loss_d"' in lines[0] and '"loss_g"' in lines[0]


def test_training_changes_the_encoder():
    maps = sample_views("topview", n=16)
    before = tiny().describe(maps)
    after = tiny(epochs=2).fit(maps).describe(maps)
    assert not np.allclose(before, after)
