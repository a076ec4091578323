"""`safl-bench bench matcher`: the scaling benchmark's figures and its checks of bad input."""

from __future__ import annotations

import json

import pytest

from safl_bench.bench import matching_bench
from safl_bench.cli import main

KEYS = ("frames", "dim", "mode", "seconds", "peak_mb", "route_found", "identical_to_dense")


def test_exact_mode_in_blocks_is_the_dense_path_and_finds_the_route(tmp_path) -> None:
    out = tmp_path / "m.json"
    assert main(["bench", "matcher", "--n", "2100", "--dim", "16", "--repeats", "1",
                 "--block-mb", "30", "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    assert all(k in res for k in KEYS)
    assert (res["frames"], res["dim"], res["mode"]) == (2100, 16, "exact")
    assert res["block_rows"] == 1024  # three blocks, and still the same numbers
    assert res["identical_to_dense"] is True and res["route_found"] == 1.0
    assert res["end_to_end"]["median_s"] > 0 and res["loop_ratio"]["ratio"] > 0


def test_candidate_mode_reports_its_agreement(tmp_path) -> None:
    pytest.importorskip("faiss")
    res = matching_bench.run(400, 16, mode="candidates", k=5, repeats=1, loop_n=20)
    assert res["mode"] == "candidates" and res["k"] == 5
    assert res["route_found"] > 0.95
    assert isinstance(res["identical_to_dense"], bool) and 0.5 < res["agree_with_dense"] <= 1


def test_without_room_for_the_dense_path_it_says_null(monkeypatch) -> None:
    monkeypatch.setattr(matching_bench, "dense_fits", lambda n: False)
    res = matching_bench.run(200, 8, repeats=1)
    assert res["identical_to_dense"] is None and res["dense"] is None
    assert "dense path: not run" in matching_bench.format_results(res)


@pytest.mark.parametrize("argv, message", [
    (["--mode", "candidates", "--k", "500", "--n", "300"], "candidates=500 is more than the database's 300 frames"),
    (["--block-mb", "0", "--n", "300"], "--block-mb must be a number of MB > 0, got '0'"),
    (["--n", "4"], "--n must be a whole number of frames >= 8, got 4"),
])
def test_bad_input_is_one_line(argv, message, capsys) -> None:
    assert main(["bench", "matcher", "--repeats", "1", *argv]) == 2
    err = capsys.readouterr().err
    assert message in err and err.count("\n") == 1
