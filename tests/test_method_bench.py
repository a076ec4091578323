"""`safl-bench bench methods`: the per-method speed figures (the paper's Table III)."""

from __future__ import annotations

from safl_bench import method_bench
from safl_bench.check import sample_views
from safl_bench.cli import main
from safl_bench.method_registry import make_method


def test_bench_method_reports_batch1_batched_and_matrix() -> None:
    views = sample_views("topview", n=12)
    result = method_bench.bench_method(make_method("sad"), views, frames=4, repeats=1, matrix_n=30)
    assert result["method"] == "sad" and result["input"] == "topview"
    assert result["batch1"]["n_items"] == 4 and result["batch1"]["per_item_ms"] > 0
    assert result["batch1"]["extra"]["batch_size"] == 1
    assert result["batched"]["n_items"] == 12 and result["batched"]["extra"]["frames_per_s"] > 0
    assert result["matrix"]["n"] == 30 and result["matrix"]["median_s"] >= 0
    ref = result["matrix"]["reference"]  # SAD's former torch.cdist, timed beside its kernel
    assert ref["name"] == "torch.cdist(p=1)" and ref["bitwise_equal"] and ref["max_abs_diff"] == 0.0
    assert "with torch.cdist(p=1) in the same run" in method_bench.format_results([result])
    table = method_bench.format_results([result])
    assert table.splitlines()[1].split()[:2] == ["sad", "topview"]
    bound = result["matrix"]["bound"]  # its absolute differences at the vector rate measured just before
    assert bound["rounds"] == 1 and bound["absdiffs"] == 30 * 30 * 32 * 32
    assert bound["bound_s"] == bound["absdiffs"] / bound["rate_per_s"] and bound["rate_per_s"] > 0
    assert bound["ratio"] == bound["matrix_s"] / bound["bound_s"] and bound["ratio_cpu"] > 0
    assert "x the bound; by CPU time" in table


def test_points_methods_are_timed_on_points() -> None:
    views = sample_views("points", n=6)
    result = method_bench.bench_method(make_method("scan_context"), views, frames=2, repeats=1, matrix_n=None)
    assert result["input"] == "points" and "matrix" not in result and result["batch1"]["per_item_ms"] > 0


def test_bench_rejects_bad_counts(capsys) -> None:  # type: ignore[no-untyped-def]
    assert main(["bench", "methods", "--repeats", "0"]) == 2
    assert "--repeats" in capsys.readouterr().err
