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
from safl_bench.training_data import SHIPPED, TrainedOn, record_seen, seen_note, trained_on
from safl_bench.weights import file_sha256

BEV02 = {"sha256": "735310183a086408aeaf65779fc26fa2c3e588698f9b94ea7b61e5679cdb7442"}


def test_the_shipped_weights_are_known_by_their_hash() -> None:
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    for path, sequences in (("methods/weights/stable_afl-bev.safetensors", ("02",)),
                            ("baselines/weights/bigan-bev.safetensors", ("02",))):
        assert SHIPPED[file_sha256(root / path)].sequences == sequences
    # the synthetic ones, retrained on data version 6, say it in their own metadata
    import json

    from safetensors import safe_open

    for path in ("methods/weights/stable_afl.safetensors", "baselines/weights/bigan.safetensors"):
        with safe_open(str(root / path), "pt") as f:
            meta = json.loads(f.metadata()["safl_bench"])
        assert trained_on(meta) == TrainedOn("synth", "synthetic default (seed 0)",
                                             ("01", "02", "03", "04"), 1), path


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


# -- weights that saw a frame range of a sequence (BEVPlace's: KITTI 00 frames 0-2999) -----------
BEVPLACE_SHIPPED = {"sha256": "66a5012eab66f5185414ef4494552f9406326f3ecd133916d58e124c3698add1"}


def _spec(n_database: int, n_queries: int, step: int = 1,
          database: tuple[int, int] | None = None, queries: tuple[int, int] | None = None) -> dict:
    """A record's task spec, as far as the frames go: ranges (BEVPlace's protocol) or none (the
    whole sequence from frame 0, every `step`-th)."""
    spec: dict = {"step": step, "n_database": n_database, "n_queries": n_queries}
    if database is not None:
        spec.update(database_frames=list(database), query_frames=list(queries or ()))
    return spec


def test_bevplace_weights_saw_kitti_00_frames_0_to_2999_only() -> None:
    from pathlib import Path

    from safl_bench.training_data import BEVPLACE_KITTI, trained_on

    root = Path(__file__).resolve().parents[1]
    assert SHIPPED[file_sha256(root / "baselines/weights/bevplace.safetensors")] == BEVPLACE_KITTI
    data = trained_on(BEVPLACE_SHIPPED)
    assert data is not None and data.sequences == ("00",) and data.frame_range("00") == (0, 2999)
    assert TrainedOn.from_dict(data.to_dict()) == data
    assert "frames" not in TrainedOn("bev", "x", ("02",), 4).to_dict()  # older dicts unchanged


def test_a_frame_range_labels_cells_seen_partly_seen_or_unseen() -> None:
    from safl_bench.training_data import (
        PARTLY_SEEN_MARK,
        PARTLY_SEEN_PREFIX,
        seen_kind,
        seen_mark,
    )

    params = {"weights": BEVPLACE_SHIPPED}
    label = "KITTI top-view images"
    # BEVPlace's protocol on 00: the whole database was trained on, none of the queries
    note = seen_note(params, "bev", label, "00", _spec(3000, 1341, 1, (0, 3000), (3200, 4541)))
    assert note is not None and note.startswith(PARTLY_SEEN_PREFIX)
    assert "whole database (3000 frames, 0\u20132999)" in note
    assert "none of the 1341 queries (3200\u20134540)" in note
    assert seen_kind(note) == "partly" and seen_mark(note) == PARTLY_SEEN_MARK
    # the whole sequence every 4th frame (revisit, paper protocol): 750 of 1136 frames were seen
    note = seen_note(params, "kitti", "KITTI", "00", _spec(1136, 1136, 4))
    assert note is not None and "750 of the 1136 database frames" in note
    assert "750 of the 1136 queries" in note
    # every frame inside the range: seen in training, not partly
    inside = seen_note(params, "bev", label, "00", _spec(100, 100, 10, (0, 1000), (2000, 3000)))
    assert inside is not None and seen_kind(inside) == "seen" and seen_mark(inside) == SEEN_MARK
    # no frame inside the range: not seen; other sequences: not seen
    assert seen_note(params, "bev", label, "00", _spec(10, 10, 1, (3000, 3010), (3100, 3110))) is None
    assert seen_note(params, "bev", label, "02", _spec(3400, 1061, 1, (0, 3400), (3600, 4661))) is None
    # a record that does not say which frames it uses: partly seen, never silently clean
    unknown = seen_note(params, "bev", label, "00")
    assert unknown is not None and seen_kind(unknown) == "partly"
    # whole-sequence training: the note of records made before frame ranges, unchanged
    assert seen_kind(seen_note({"weights": BEV02}, "bev", label, "02")) == "seen"
    assert seen_kind(None) is None and seen_mark(None) == ""


def test_a_partly_seen_cell_is_its_own_row_never_ranked_and_explained() -> None:
    from safl_bench.leaderboard.tables import PARTLY_SEEN_MARK, bevplace_table
    from safl_bench.training_data import record_seen

    spec = _spec(3000, 1341, 1, (0, 3000), (3200, 4541))
    clean = [scored_record(m, seed=s, skill=k, source_kind="bev", sequence="00", protocol="bevplace",
                           source_label="KITTI top-view images")
             for m, k in (("sad", 0.5), ("bevplace", 0.9)) for s in range(2)]
    clean = [dataclasses.replace(r, task=dataclasses.replace(r.task, spec=spec)) for r in clean]
    partly = [dataclasses.replace(r, method=dataclasses.replace(r.method,
                                                                params={"weights": BEVPLACE_SHIPPED}))
              for r in clean if r.method.name == "bevplace"]
    assert all(record_seen(r) for r in partly)
    table = bevplace_table(table_key(clean[0]), [r for r in clean if r.method.name == "sad"] + partly)
    rows = {row[:2]: i for i, row in enumerate(table.rows)}
    assert ("bevplace", "1" + PARTLY_SEEN_MARK) in rows and ("sad", "1") in rows
    mine = rows[("bevplace", "1" + PARTLY_SEEN_MARK)]
    assert not any(i == mine for i, _ in table.marks)  # better, yet never marked best
    note = next(n for n in table.notes if "partly seen in training" in n)
    assert "bevplace on 00: the whole database (3000 frames" in note
    assert not any("'seen in training'" in n for n in table.notes)  # no fully seen row here
