"""Training data tracked: weights record their sequences, records on those sequences are marked,
and the leaderboard never ranks them beside clean cells (`safl_bench.training_data`)."""

from __future__ import annotations

import dataclasses

import numpy as np
from record_factory import scored_record

from safl_bench.leaderboard.grouping import table_key
from safl_bench.leaderboard.tables import SEEN_MARK, recall_table
from safl_bench.method import Method
from safl_bench.method_registry import make_method
from safl_bench.training_data import SHIPPED, TrainedOn, record_seen, seen_note
from safl_bench.weights import file_sha256

BEV02 = {"sha256": "735310183a086408aeaf65779fc26fa2c3e588698f9b94ea7b61e5679cdb7442"}


def test_the_shipped_weights_are_known_by_their_hash() -> None:
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    for path, sequences in (("methods/weights/stable_afl-bev.safetensors", ("02",)),
                            ("baselines/weights/bigan-bev.safetensors", ("02",)),
                            ("methods/weights/stable_afl.safetensors", ("01", "02", "03", "04"))):
        assert SHIPPED[file_sha256(root / path)].sequences == sequences


def test_seen_on_the_trained_sequence_of_the_same_data_only() -> None:
    params = {"weights": BEV02}
    note = seen_note(params, "bev", "KITTI top-view images", "02")
    assert note is not None and "KITTI 02" in note and "this task's sequence 02" in note
    assert seen_note(params, "kitti", "KITTI", "02") is not None  # the same drive as scans
    assert seen_note(params, "bev", "KITTI top-view images", "00") is None
    assert seen_note(params, "synth", "synthetic default (seed 0)", "02") is None
    synth = {"weights": {"trained_on": TrainedOn("synth", "synthetic default (seed 0)",
                                                 ("01", "02")).to_dict()}}
    assert seen_note(synth, "synth", "synthetic default (seed 0)", "02") is not None
    assert seen_note(synth, "synth", "synthetic default (seed 3)", "02") is None
    assert seen_note({"weights": {"source": "untrained"}}, "bev", "x", "02") is None
    assert seen_note({}, "bev", "x", "02") is None


def test_weights_record_what_they_were_trained_on(tmp_path) -> None:
    method = make_method("bigan@1", weights="untrained", width=4, encoder_width=4, code_size=8,
                         hidden=8)
    data = TrainedOn("bev", "KITTI top-view images", ("00", "02"), 4)
    path = method.save(tmp_path / "w.safetensors", parts=("encoder",), trained_on=data.to_dict())
    loaded = Method.load(path)
    assert loaded.weights_info is not None
    assert TrainedOn.from_dict(loaded.weights_info["trained_on"]) == data
    assert "trained_on" not in (Method.load(method.save(tmp_path / "v.safetensors")).weights_info or {})


def test_a_seen_cell_is_its_own_row_and_never_ranked() -> None:
    clean = [scored_record(m, seed=s, skill=k, source_kind="bev", sequence="02",
                           source_label="KITTI top-view images")
             for m, k in (("sad", 0.5), ("stable_afl", 0.9)) for s in range(2)]
    seen = [dataclasses.replace(r, method=dataclasses.replace(
                r.method, params={"weights": BEV02}))
            for r in clean if r.method.name == "stable_afl"]
    assert all(record_seen(r) for r in seen) and not any(record_seen(r) for r in clean)
    table = recall_table(table_key(clean[0]), [r for r in clean if r.method.name == "sad"] + seen)
    rows = {row[:2]: i for i, row in enumerate(table.rows)}
    assert ("stable_afl", "1" + SEEN_MARK) in rows and ("sad", "1") in rows
    mine = rows[("stable_afl", "1" + SEEN_MARK)]
    assert not any(i == mine for i, _ in table.marks)  # better, yet never marked best
    assert any("seen in training" in note for note in table.notes)
    assert np.isfinite(table.cells[mine][0].mean)


def test_train_on_the_test_sequence_warns_in_one_line_and_records_it(tmp_path, monkeypatch,
                                                                      capsys) -> None:
    from conftest import write_bev

    from safl_bench.cli import main
    from safl_bench.cli import train as train_cli

    root = write_bev(tmp_path / "bev", n=12)
    maps = np.random.default_rng(0).random((12, 41, 41)).astype(np.float32)
    monkeypatch.setattr(train_cli, "load_training_maps", lambda *a, **k: (maps, {"00": 12}))
    out = tmp_path / "run"
    assert main(["train", "--method", "bigan@1", "--bev-root", str(root), "--sequences", "00",
                 "--epochs", "1", "--batch-size", "4", "--out", str(out), "--no-progress",
                 "--val-task", "none", "--set", "width=4", "--set", "encoder_width=4",
                 "--set", "code_size=8", "--set", "hidden=8"]) == 0
    warnings = [line for line in capsys.readouterr().err.splitlines() if "warning" in line]
    assert len(warnings) == 1 and "training on 00" in warnings[0]
    loaded = Method.load(out / "bigan.safetensors")
    data = TrainedOn.from_dict(loaded.weights_info["trained_on"])
    assert data is not None and data.sequences == ("00",) and data.source_kind == "bev"
    assert seen_note({"weights": loaded.weights_info}, "bev", "KITTI top-view images", "00")


def test_train_without_out_writes_a_folder_per_version(tmp_path, monkeypatch, safl_home) -> None:
    """The default run folder names the method's version: training bigan@1 and then bigan@2
    with no --out never finds the other's checkpoint there."""
    from conftest import write_bev

    from safl_bench.cli import main
    from safl_bench.cli import train as train_cli

    root = write_bev(tmp_path / "bev", n=12)
    maps = np.random.default_rng(0).random((12, 41, 41)).astype(np.float32)
    monkeypatch.setattr(train_cli, "load_training_maps", lambda *a, **k: (maps, {"02": 12}))
    assert main(["train", "--method", "bigan@1", "--bev-root", str(root), "--sequences", "02",
                 "--epochs", "1", "--batch-size", "4", "--no-progress", "--val-task", "none",
                 "--set", "width=4", "--set", "encoder_width=4", "--set", "code_size=8",
                 "--set", "hidden=8"]) == 0
    (run,) = (safl_home / "weights").iterdir()
    assert run.name == "bigan-v1-bev-seed0" and (run / "bigan.safetensors").is_file()
