"""The matcher's scaling runs on the board (`safl_bench.leaderboard.scaling`)."""

from __future__ import annotations

import json
from pathlib import Path

from safl_bench.leaderboard import scaling


def run(frames: int, mode: str = "exact", dense: bool = True) -> dict:
    return {"frames": frames, "dim": 256, "mode": mode, "seconds": frames / 1e4,
            "peak_mb": frames / 100, "route_found": 1.0,
            "identical_to_dense": (mode == "exact") if dense else None,
            "agree_with_dense": 0.9 if dense else None, "k": 10 if mode == "candidates" else None,
            "index": "flat" if mode == "candidates" else None,
            "dense": {"seconds": frames / 5e3, "peak_mb": frames / 10} if dense else None,
            "timing": {"env": {"load_avg_1m": 1.2}}}


def test_runs_become_a_table_and_a_figure(tmp_path: Path) -> None:
    folder = tmp_path / scaling.FOLDER
    folder.mkdir(parents=True)
    for i, r in enumerate([run(1000), run(100_000, dense=False), run(1000, "candidates")]):
        (folder / f"{i}.json").write_text(json.dumps(r))
    (folder / "broken.json").write_text("{")
    (folder / "other.json").write_text(json.dumps({"frames": 3}))
    runs, problems = scaling.load(folder)
    assert [r["frames"] for r in runs] == [1000, 100_000, 1000]  # exact first
    assert sorted(p.path.name for p in problems) == ["broken.json", "other.json"]
    assert "no dim, mode, seconds" in str(next(p for p in problems if p.path.name == "other.json"))
    md = scaling.markdown(runs)
    assert "| 100,000 | 256 | exact (blocks) | 10.00 | 1000 | 100.0 % | n/a | n/a |" in md
    assert "candidates (k=10, flat)" in md and "no (90.0 % same frame)" in md
    scaling.figure(runs, tmp_path / "curve.png")
    assert (tmp_path / "curve.png").stat().st_size > 1000


def test_no_folder_no_runs(tmp_path: Path) -> None:
    assert scaling.load(tmp_path / "nothing") == ([], [])
