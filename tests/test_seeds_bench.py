"""`safl-bench bench seeds`: five seeds of a cell against one, and the interval overhead."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from conftest import write_bev

from safl_bench import seeds_bench
from safl_bench.cli import main


def test_bench_seeds_prints_both_ratios_and_the_interval_share(tmp_path: Path, safl_home: Path,
                                                               capsys: pytest.CaptureFixture[str]) -> None:
    home = os.environ.get("SAFL_HOME")
    # 80 frames at every 4th: 20 queries, the last 10 scored (the first 10 are context)
    bev_root = write_bev(tmp_path / "bev", n=80)
    result = seeds_bench.run(str(bev_root), ["sad"], repeats=1)
    assert os.environ.get("SAFL_HOME") == home  # each run's scratch home is undone
    figures = result["methods"]["sad"]
    assert len(figures["one_s"]) == len(figures["shared_s"]) == len(figures["alone_cpu_s"]) == 1
    assert figures["cpu_ratio_shared"] == pytest.approx(figures["shared_cpu_s"][0] / figures["one_cpu_s"][0])
    assert figures["ratio_shared"] == pytest.approx(figures["shared_s"][0] / figures["one_s"][0])
    assert figures["ratio_alone"] == pytest.approx(figures["alone_s"][0] / figures["one_s"][0])
    assert 0 < figures["interval_share"] < 1
    text = seeds_bench.format_results(result)
    assert "sad: one seed" in text and "process CPU time" in text and "(target <= 2.5x)" in text and "(target <= 5 %)" in text


def test_bench_seeds_needs_images_and_a_task_with_seeds(monkeypatch: pytest.MonkeyPatch,
                                                        capsys: pytest.CaptureFixture[str]) -> None:
    monkeypatch.delenv("SAFL_BEV_ROOT", raising=False)
    assert main(["bench", "seeds"]) == 2
    err = capsys.readouterr().err.strip()
    assert "bench seeds needs --bev-root DIR" in err and len(err.splitlines()) == 1
    assert main(["bench", "seeds", "--bev-root", "x", "--task", "SAFL/BEVKITTI00-Revisit-v0"]) == 2
    assert "has one seed" in capsys.readouterr().err
