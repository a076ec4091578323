"""Leaderboard tables and figures from hand-made records: exact cells, missing cells, seeds,
task versions and data sources kept apart, and byte-identical regeneration."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from record_factory import SYNTH_LABEL, make_record, scored_record, task_outcomes

from safl_bench.cli import main as cli_main
from safl_bench.errors import DataError
from safl_bench.leaderboard import build_leaderboard
from safl_bench.leaderboard.grouping import Cell, aggregate, condition_order, group_records
from safl_bench.leaderboard.tables import (
    auc_table,
    bevplace_table,
    recall_at_1_table,
    recall_table,
    revisit_table,
    time_table,
)
from safl_bench.leaderboard.training_logs import read_training_log
from safl_bench.records import ResultRecord, load_records, write_record


def _paper_records() -> list[ResultRecord]:
    """Two methods on T1R1 and T5R1; 'sad' lacks T5R1."""
    return [
        make_record("stable_afl", condition="T1R1", recall=0.909, auc=0.95, ms=16.1),
        make_record("stable_afl", condition="T5R1", recall=0.584, auc=0.90, ms=15.8),
        make_record("sad", condition="T1R1", recall=0.283, auc=0.80, ms=3.2, single_recall=0.3),
    ]


def _table(records: list[ResultRecord], build=recall_table):
    groups, notes = group_records(records)
    assert len(groups) == 1
    ((key, group),) = groups.items()
    return build(key, group, notes[key])


def _rows(markdown: str) -> list[str]:
    return [line for line in markdown.splitlines() if line.startswith("| ")]


def test_recall_table_has_exact_cells_and_dashes_for_missing() -> None:
    md = _table(_paper_records()).markdown()
    assert md.startswith(
        f"## Recall at 100 % precision (%) — {SYNTH_LABEL}, sequence 00, paper protocol, "
        "task version v0\n"
    )
    # records without per-query outcomes: no interval, so no order beyond the noise (tied, ≈)
    assert _rows(md) == [
        "| Method | Version | Matching | T1R1 | T5R1 |",
        "| sad | 1 | sequence | ≈ 28.3 | — |",
        "| sad | 1 | single-frame | ≈ 30.0 | — |",
        "| stable_afl | 1 | sequence | ≈ 90.9 | 58.4 |",
        "| stable_afl | 1 | single-frame | ≈ 45.5 | 29.2 |",
    ]
    assert any("Cells without an interval" in note for note in _table(_paper_records()).notes)
    assert "nan" not in md.lower()


def test_csv_has_numbers_source_and_empty_missing_cells() -> None:
    csv = _table(_paper_records()).csv().splitlines()
    assert csv[0] == ("Source,Protocol,Sequence,Task version,Method,Version,Matching,T1R1,T1R1 low,"
                      "T1R1 high,T1R1 rank,T5R1,T5R1 low,T5R1 high,T5R1 rank,Seeds")
    assert csv[1] == f"{SYNTH_LABEL},paper,00,0,sad,1,sequence,28.3,,,tied,,,,,0"
    assert csv[4] == f"{SYNTH_LABEL},paper,00,0,stable_afl,1,single-frame,45.5,,,tied,29.2,,,,0"


def test_auc_and_time_tables() -> None:
    records = _paper_records()
    auc = _rows(_table(records, auc_table).markdown())
    assert auc[1] == "| sad | 1 | sequence | ≈ 0.800 | — |"
    assert auc[4] == "| stable_afl | 1 | single-frame | ≈ 0.855 | 0.810 |"
    timing = _table(records, time_table)
    rows = _rows(timing.markdown())
    assert rows == [
        "| Method | Version | T1R1 | T5R1 |",
        "| sad | 1 | 3.20 | — |",
        "| stable_afl | 1 | 16.10 | 15.80 |",
    ]
    assert any("Test CPU (2 cores; vector sets not recorded)" in note for note in timing.notes)
    assert not any("different machines" in note for note in timing.notes)


def test_a_cell_timed_on_two_hosts_shows_its_lowest_seeds_timing_and_says_so() -> None:
    """Seeds run later on a slower host carry their own timing; the cell is not their mean."""
    import dataclasses

    def on(record: ResultRecord, vector: str) -> ResultRecord:
        return dataclasses.replace(
            record, environment=dataclasses.replace(record.environment, cpu_vector=vector))

    def retimed(record: ResultRecord) -> ResultRecord:
        how = (f"{record.timings.how_run}; timed by the run of 2026-12-01T21:43:31Z (git abc); "
               "rescored with metrics version 3")
        return dataclasses.replace(record, timings=dataclasses.replace(record.timings, how_run=how))

    records = [on(retimed(make_record("bevplace", seed=0, ms=97.0)), "avx2 fma avx512f"),
               on(make_record("bevplace", seed=1, ms=342.0), "avx2 fma"),
               on(make_record("sad", seed=0, ms=3.0), "avx2 fma avx512f"),
               on(make_record("sad", seed=1, ms=3.0), "avx2 fma avx512f")]
    timing = _table(records, time_table)
    assert _rows(timing.markdown())[1:] == ["| bevplace | 1 | 97.00 (seed 0) |",
                                           "| sad | 1 | 3.00 (1 timing) |"]
    note = next(n for n in timing.notes if "different machines" in n)
    assert "bevplace v1, T1R1: Test CPU (2 cores; avx2 fma avx512f) / Test CPU (2 cores; avx2 fma)" in note
    assert "sad" not in note
    # the seed left out was run: the note on the cell's seeds does not ask to run it
    seeds = next(n for n in timing.notes if "over seed(s) 0 only" in n)
    assert "timed on another host" in seeds and "run the missing seeds" not in seeds
    # how the rows were timed, once; which run timed each record stays in the records
    runs = next(n for n in timing.notes if n.startswith("Measured on"))
    assert runs.count("sequential, pinned") == 1 and "timed by the run of" not in runs


def test_a_cell_with_other_seeds_than_the_table_names_them() -> None:
    records = [
        make_record("a", condition="T1R1", seed=0, recall=0.5),
        make_record("a", condition="T1R1", seed=1, recall=0.7),
        make_record("a", condition="T5R1", seed=0, recall=0.4),  # seed 1 missing
    ]
    table = _table(records)
    rows = _rows(table.markdown())
    assert rows[1] == "| a | 1 | sequence | 60.0 | 40.0 (seed 0) |"
    assert any("T5R1 over seed(s) 0 only (the table's: 0, 1)" in note for note in table.notes)
    assert "Mean over seeds 0, 1 [95 % interval over seeds and queries]" in table.markdown()
    header = table.csv().splitlines()[0].split(",")
    assert {"T1R1 low", "T1R1 high", "T5R1 seeds"} <= set(header) and "T1R1 seeds" not in header


def test_records_predating_a_setting_share_the_configuration_of_its_default() -> None:
    """A record made before `truth_at` and `distance` existed was scored with their defaults:
    the table names one configuration, not two; a real difference is still named."""
    import dataclasses

    from safl_bench.matching.settings import EvaluationConfig

    now = EvaluationConfig().to_dict()
    before = {**now, "evaluation": {k: v for k, v in now["evaluation"].items()
                                    if k not in ("truth_at", "distance")}}
    other = {**now, "evaluation": {**now["evaluation"], "truth_at": "viewpoint"}}

    def with_matcher(seed: int, matcher: dict) -> ResultRecord:
        return dataclasses.replace(make_record("a", seed=seed), matcher=matcher)

    notes = _table([with_matcher(0, before), with_matcher(1, now)]).notes
    assert any(n.startswith("Matcher preset (all rows): paper-r10;") for n in notes)
    assert not any("differ" in n for n in notes)
    notes = _table([with_matcher(0, before), with_matcher(1, other)]).notes
    assert any(n.startswith("Matcher settings differ between records (2 configurations") for n in notes)


def test_cells_carry_bootstrap_intervals_and_bold_means_better_beyond_the_noise() -> None:

    records = [scored_record(m, seed=s, skill=k, variant=v, condition="T1R1")
               for m, k, v in (("strong", 0.95, 0), ("weak", 0.3, 0)) for s in range(3)]
    records += [scored_record(m, seed=s, skill=0.6, variant=v, condition="T5R1")
                for m, v in (("strong", 1), ("weak", 2)) for s in range(3)]
    table = _table(records, recall_at_1_table)
    (t1,) = [j for j, c in enumerate(table.columns) if c == "T1R1"]
    (t5,) = [j for j, c in enumerate(table.columns) if c == "T5R1"]
    strong = table.rows.index(("strong", "1", "sequence"))
    weak = table.rows.index(("weak", "1", "sequence"))
    cell = table.cells[strong][t1]
    assert cell is not None and cell.low is not None and cell.high is not None
    assert cell.low < cell.mean < cell.high and cell.seeds == frozenset({0, 1, 2})
    md = table.markdown()
    text = table.cell_text(cell, table.formats[t1])
    assert f"| strong | 1 | sequence | **{text}** |" in md  # a resolved difference: bold alone
    assert table.marks[(strong, t1)] == "best" and (weak, t1) not in table.marks
    # same skill, other draws: not resolved, both marked tied, neither bold
    assert table.marks[(strong, t5)] == table.marks[(weak, t5)] == "tied"
    assert "≈ " + table.cell_text(table.cells[weak][t5], table.formats[t5]) in md
    # one seed of one method: compared on the seed both have, and named in its cell
    lone = [r for r in records if not (r.method.name == "weak" and r.seed > 0)]
    table = _table(lone, recall_at_1_table)
    weak = table.rows.index(("weak", "1", "sequence"))
    assert "(seed 0)" in table.cell_text(table.cells[weak][t1], table.formats[t1])
    assert table.marks[(table.rows.index(("strong", "1", "sequence")), t1)] == "best"


def test_aggregate_rules() -> None:
    assert aggregate({}) is None
    assert aggregate({0: 0.5, 1: None}) == Cell(None, seeds=frozenset({0, 1}))
    assert aggregate({0: 0.5, 3: 0.7}) == Cell(pytest.approx(0.6), seeds=frozenset({0, 3}))


def test_task_versions_and_sources_are_never_mixed() -> None:
    records = [
        make_record("a", condition="T1R1", task_version=0, recall=0.5),
        make_record("a", condition="T1R1", task_version=1, recall=0.9),
        make_record("a", condition="T1R1", source_kind="kitti", source_label="KITTI", recall=0.2),
    ]
    groups, _ = group_records(records)
    assert [(k.source_label, k.task_version) for k in groups] == [
        ("KITTI", 0),
        (SYNTH_LABEL, 0),
        (SYNTH_LABEL, 1),
    ]
    texts = {k: recall_table(k, g).markdown() for k, g in groups.items()}
    for key, md in texts.items():
        assert key.source_label in md.splitlines()[0]
        assert f"task version v{key.task_version}" in md.splitlines()[0]
        assert len(_rows(md)) == 3  # header + one method in two modes: nothing from other groups
    v1 = next(md for k, md in texts.items() if k.task_version == 1)
    assert "| a | 1 | sequence | 90.0 |" in v1 and "50.0" not in v1


def test_records_of_an_older_task_spec_are_left_out_with_a_note() -> None:
    records = [
        make_record("a", condition="T1R1", spec_fingerprint="old", created="2025-01-01T00:00:00Z"),
        make_record("b", condition="T1R1", spec_fingerprint="new", created="2025-02-01T00:00:00Z"),
    ]
    table = _table(records)
    assert [r[0] for r in table.rows] == ["b", "b"]
    assert any("older spec" in note and "a v1 seed 0" in note for note in table.notes)


def test_revisit_table() -> None:
    records = [
        make_record("a", protocol="revisit", sequence="00", recall=0.5, auc=0.9, f1=0.8, recall_at_1=0.9),
        make_record("a", protocol="revisit", sequence="09", recall=0.4, auc=0.8, f1=0.6),
        make_record("b", protocol="revisit", sequence="00", recall=0.3, auc=0.7, f1=0.5),
    ]
    md = _table(records, revisit_table).markdown()
    assert "revisit protocol, task version v0" in md.splitlines()[0]
    rows = _rows(md)
    assert rows[0] == (
        "| Method | Version | Matching | 00 F1max | 00 R@100%P (%) | 00 AUC | 00 R@1 (%) "
        "| 09 F1max | 09 R@100%P (%) | 09 AUC | 09 R@1 (%) |"
    )
    assert rows[1] == ("| a | 1 | sequence | ≈ 0.800 | ≈ 50.0 | ≈ 0.900 | 90.0 | 0.600 | 40.0 "
                       "| 0.800 | n/a |")
    assert rows[3] == "| b | 1 | sequence | ≈ 0.500 | ≈ 30.0 | ≈ 0.700 | n/a | — | — | — | — |"


def test_bevplace_table_and_the_published_rows_beside_it(tmp_path) -> None:
    records = [
        make_record("sad", protocol="bevplace", condition=None, sequence=s, source_kind="bev",
                    source_label="KITTI top-view images", recall_at_1=r)
        for s, r in (("00", 0.8), ("02", 0.6))
    ]
    md = _table(records, bevplace_table).markdown()
    rows = _rows(md)
    assert rows[0].startswith("| Method | Version | Matching | 00 R@1 (%) | 00 R@5 (%) | 00 R@10 (%)")
    assert rows[2].startswith("| sad | 1 | single-frame | 40.0 | 50.0 | n/a | 0.350 | 30.0 |")
    build_leaderboard(records, tmp_path / "lb", figures=False)
    index = (tmp_path / "lb" / "index.md").read_text()
    assert "BEVPlace's protocol: Recall@1, @5, @10 and F1max" in index  # inline for real KITTI
    assert "| BEVPlace (published) | 99.7 | 98.1 | 99.3 | 100.0 |" in index
    assert "not run here" in index


def test_condition_order_follows_the_paper() -> None:
    assert condition_order(["T20R2", "T1R1.5", "T5R1", "T1R1", "T0R0"]) == [
        "T1R1",
        "T5R1",
        "T1R1.5",
        "T20R2",
        "T0R0",
    ]


def _write_all(results: Path, records: list[ResultRecord]) -> None:
    for record in records:
        write_record(results, record)


SRC = "synthetic-default-seed-0"


def _files(root: Path) -> dict[str, bytes]:
    return {
        str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*")) if p.is_file()
    }


def test_tables_are_deterministic_and_stale_files_removed(tmp_path: Path) -> None:
    records = [*_paper_records(), make_record("stable_afl", protocol="revisit", sequence="00")]
    out1, out2 = tmp_path / "lb1", tmp_path / "lb2"
    build_leaderboard(records, out1, figures=False, site=False)
    report = build_leaderboard(list(reversed(records)), out2, figures=False, site=False)
    files = _files(out1)
    assert files == _files(out2)
    assert set(files) == {
        "index.md",
        "tables/all-results.csv",
        *(
            f"tables/{SRC}/paper-00-v0-{t}.{ext}"
            for t in ("recall", "f1max", "recall-at-1", "auc", "time")
            for ext in ("md", "csv")
        ),
        f"tables/{SRC}/revisit-v0.md",
        f"tables/{SRC}/revisit-v0.csv",
    }
    # the revisit protocol heads the board (what the field reports), the paper's tables follow
    assert report.headline is not None and report.headline.key.protocol == "revisit"
    index = files["index.md"].decode()
    assert "## Headline" in index and "Protocol: revisit" in index.split("## Headline")[1]
    recall = files[f"tables/{SRC}/paper-00-v0-recall.md"].decode()
    assert "| stable_afl | 1 | sequence | ≈ 90.9 | 58.4 |" in recall
    # Regenerating without the revisit record removes its table and keeps hand-written files.
    (out1 / "README.md").write_text("hand-written\n")
    report = build_leaderboard(records[:3], out1, figures=False, site=False)
    assert not (out1 / f"tables/{SRC}/revisit-v0.md").exists()
    assert [p.name for p in report.removed] == ["revisit-v0.csv", "revisit-v0.md"]
    assert (out1 / "README.md").read_text() == "hand-written\n"


def test_figures_are_written_and_reproducible(tmp_path: Path) -> None:
    records = [make_record("stable_afl", condition="T1R1")]
    logs = tmp_path / "logs" / "stable_afl"
    logs.mkdir(parents=True)
    lines = [
        {
            "epoch": e,
            "losses": {"g": 1.0},
            "val_auc": {"T1R1": 0.6 + 0.1 * e},
            "source": SYNTH_LABEL,
        }
        for e in range(3)
    ]
    (logs / "train_log.jsonl").write_text("".join(json.dumps(x) + "\n" for x in lines))
    out1, out2 = tmp_path / "lb1", tmp_path / "lb2"
    build_leaderboard(records, out1, training_logs=tmp_path / "logs")
    build_leaderboard(records, out2, training_logs=tmp_path / "logs")
    files = _files(out1)
    assert files == _files(out2)
    pngs = {name for name in files if name.endswith(".png")}
    assert pngs == {
        f"figures/{SRC}/paper-00-v0-auc-heatmap.png",
        f"figures/{SRC}/paper-00-v0-pr-stable-afl-v1.png",
        f"figures/training-stability-{SRC}.png",
    }
    assert all(files[name].startswith(b"\x89PNG") for name in pngs)
    assert b"Software" not in files[f"figures/{SRC}/paper-00-v0-auc-heatmap.png"]
    assert (
        f"[{SYNTH_LABEL}](figures/training-stability-{SRC}.png): stable_afl"
        in files["index.md"].decode()
    )


def test_empty_results_never_wipe_a_leaderboard(tmp_path: Path) -> None:
    with pytest.raises(DataError, match="no result records"):
        build_leaderboard([], tmp_path)


def test_cli_reports_corrupt_records_and_rebuilds(tmp_path: Path, capsys) -> None:
    out = tmp_path / "leaderboard"
    records_dir = out / "records"
    _write_all(records_dir, _paper_records())
    bad = records_dir / "broken@1" / "SAFL__Synth00-T1R1-v0" / "seed-0.json"
    bad.parent.mkdir(parents=True)
    bad.write_text('{"schema": 1, "method": ')
    assert cli_main(["leaderboard", "--out", str(out), "--no-figures"]) == 2  # built from the rest
    captured = capsys.readouterr()
    assert str(bad) in captured.err and "not valid JSON" in captured.err
    assert "| stable_afl | 1 | sequence | ≈ 90.9 | 58.4 |" in captured.out
    # a board built away from a checkout names what it leaves out, and why
    assert f"{out} has no preset-records/ (the tables by matcher preset and Table II)" in captured.err
    assert "training-logs/ (the training curves)" in captured.err
    index = (out / "index.md").read_text()
    assert "broken@1/SAFL__Synth00-T1R1-v0/seed-0.json" in index
    first = {p: p.read_bytes() for p in out.rglob("*.md")}
    assert cli_main(["leaderboard", "--out", str(out), "--no-figures"]) == 2
    assert {p: p.read_bytes() for p in out.rglob("*.md")} == first


def test_cli_without_records_fails_cleanly(tmp_path: Path, capsys) -> None:
    assert cli_main(["leaderboard", "--out", str(tmp_path / "lb")]) == 2
    assert "no result records" in capsys.readouterr().err


def test_training_log_bad_lines_are_reported(tmp_path: Path) -> None:
    path = tmp_path / "m" / "train_log.jsonl"
    path.parent.mkdir()
    path.write_text(
        '{"epoch": 0, "val_auc": {"T1R1": 0.5}}\n'
        '{"epoch": 1, "val_auc": {"T1R1": NaN}}\n'
        '{"epoch": 2, "val_auc": {"T1R1": 0.7}}\n'
        '{"epoch": 2, "val_auc": {"T1R1": 0.8}}\n'
        '{"epoch": 3, "val_au'
    )
    log, problems = read_training_log(path)
    assert log is not None and log.epochs == [0, 2] and log.val_auc["T1R1"] == [0.5, 0.8]
    assert log.source is None
    assert [p.reason.split(":")[0] for p in problems] == ["line 2", "line 5"]


REPO_BOARD = Path(__file__).resolve().parents[1] / "leaderboard"


def _committed(build: Path, subdirs: tuple[str, ...]) -> None:
    for sub in subdirs:
        made = _files(build / sub) if (build / sub).is_dir() else {}
        kept = _files(REPO_BOARD / sub) if (REPO_BOARD / sub).is_dir() else {}
        assert sorted(made) == sorted(kept), f"{sub}: regenerate with `safl-bench leaderboard`"
        for name in made:
            assert made[name] == kept[name], f"{sub}/{name} differs from a regeneration"


def test_committed_tables_are_regenerated_exactly(tmp_path: Path) -> None:
    records, problems = load_records(REPO_BOARD / "records")
    if not records:
        pytest.skip("no committed records in leaderboard/records yet")
    assert problems == []
    from safl_bench.cli.leaderboard import load_preset_records

    presets, bad = load_preset_records(REPO_BOARD)
    assert bad == []
    from safl_bench.leaderboard import table2

    variants, _ = table2.load_variants(REPO_BOARD / "experiments" / "table2")
    selected, _ = load_records(REPO_BOARD / "selected-records")
    report = build_leaderboard(records, tmp_path, figures=False, preset_records=presets,
                               selected_records=selected, table2_variants=variants,
                               records_folder=lambda record: str(REPO_BOARD / "records"),
                               scaling_dir=REPO_BOARD / "experiments" / "matcher-scaling")
    _committed(tmp_path, ("tables",))
    # the README's generated blocks are what the same records give (`safl-bench leaderboard`)
    from safl_bench.leaderboard.headline import README_LINK, readme_block

    readme = (REPO_BOARD.parent / "README.md").read_text(encoding="utf-8")
    assert report.headline is not None
    assert readme_block(report.headline, report.headline_records, README_LINK) in readme
    side, rel = report.table2[min(report.table2)]
    assert table2.readme_block(side, rel) in readme
    # and so are the guides' generated blocks (`safl_bench.leaderboard.guides`)
    from safl_bench.leaderboard.guides import blocks

    for block, text in blocks(report):
        guide = (REPO_BOARD.parent / block.guide).read_text(encoding="utf-8")
        assert block.start in guide, f"{block.guide}: the {block.name} block's markers are gone"
        assert text in guide, f"{block.guide}: the {block.name} block is stale; run `safl-bench leaderboard`"


@pytest.mark.slow
def test_committed_leaderboard_is_regenerated_exactly(tmp_path: Path) -> None:
    records, problems = load_records(REPO_BOARD / "records")
    if not records:
        pytest.skip("no committed records in leaderboard/records yet")
    from safl_bench.cli.leaderboard import load_preset_records

    build_leaderboard(
        records, tmp_path, training_logs=REPO_BOARD / "training-logs", skipped=problems,
        preset_records=load_preset_records(REPO_BOARD)[0],
    )
    _committed(tmp_path, ("tables", "figures", "site"))
    assert (tmp_path / "index.md").read_bytes() == (REPO_BOARD / "index.md").read_bytes()


def test_equal_values_are_neither_bold_nor_tied() -> None:
    records = [make_record(m, condition="T1R1", recall=0.5) for m in ("a", "b")]
    table = _table(records)
    assert table.marks == {} and "≈ 50" not in table.markdown()
    assert not any("**" in row for row in _rows(table.markdown()))


def test_real_kitti_paper_tables_gain_one_table_by_matcher_preset(tmp_path) -> None:
    from dataclasses import replace

    from safl_bench.matcher_presets import configure

    def record(preset: str, recall: float, condition: str) -> object:
        base = make_record("sad", condition=condition, source_kind="bev",
                           source_label="KITTI top-view images", recall=recall, recall_at_1=0.8)
        return replace(base, matcher=configure(preset).to_dict())

    paper = [record("paper", 0.0, c) for c in ("T1R1", "T5R1")]
    authors = [record("authors", 0.4, c) for c in ("T1R1", "T5R1")]
    build_leaderboard(paper, tmp_path / "lb", figures=False, preset_records=authors)
    md = (tmp_path / "lb/tables/kitti-top-view-images/paper-00-v0-presets-recall.md").read_text()
    rows = _rows(md)
    assert rows[0] == "| Method | Version | Matcher · scored queries | T1R1 | T5R1 |"
    assert rows[1:] == ["| sad | 1 | authors · 100 queries | 40.0 | 40.0 |",
                        "| sad | 1 | paper · 100 queries | 0.0 | 0.0 |"]  # sorted by name
    assert "Sequence matcher by preset" in (tmp_path / "lb/index.md").read_text()


def test_table_ii_side_by_side_reads_the_authors_presets_and_says_which_cells_hold_the_paper(tmp_path) -> None:
    """Under the authors' paper-era presets (authors-sad for SAD, authors for the learned
    features) each cell's mean [interval] stands beside the paper's value, with whether the
    paper's value is inside; records of any other preset are not read; the site shows it too."""
    from dataclasses import replace

    from safl_bench.leaderboard import table2
    from safl_bench.matching.presets import configure

    def record(method: str, preset: str, seed: int, skill: float) -> object:
        base = scored_record(method, seed=seed, skill=skill, condition="T1R1", source_kind="bev",
                             source_label="KITTI top-view images")
        return replace(base, matcher=configure(preset).to_dict())

    paper = [record("sad", "paper", s, 0.7) for s in range(2)]
    presets = [record("sad", "authors-sad", s, 0.99) for s in range(2)]
    presets += [record("stable_afl", "authors", s, 0.99) for s in range(2)]
    presets += [record("bigan", "authors-sad", s, 0.99) for s in range(2)]  # not BiGAN's preset
    rows = table2.side_by_side([*paper, *presets])
    by = {(r.method, r.condition): r for r in rows}
    assert [r.method for r in rows if r.condition == "T1R1"] == ["sad", "stable_afl"]
    sad, safl = by[("sad", "T1R1")], by[("stable_afl", "T1R1")]
    assert sad.paper == 28.3 and safl.paper == 90.9 and sad.seeds == (0, 1)
    iv = sad.ours["recall_at_100_precision"]
    assert iv is not None and iv.low <= iv.mean <= iv.high
    assert sad.inside("recall_at_100_precision") == (iv.low * 100 - 0.05 <= 28.3 <= iv.high * 100 + 0.05)
    assert by[("sad", "T5R1")].seeds == () and by[("sad", "T5R1")].inside("recall_at_100_precision") is None
    build_leaderboard(paper, tmp_path / "lb", figures=False, preset_records=presets)
    md = (tmp_path / "lb/tables/kitti-top-view-images/paper-00-v0-table2-side-by-side.md").read_text()
    assert md.startswith("# Table II side by side") and "| SAD | 1 | T1R1 | 28.3 | 0,1 |" in md
    assert "| BiGAN |" not in md and "not run" in md
    page = (tmp_path / "lb/site/kitti-top-view-images-paper-00-v0.html").read_text()
    assert '<section class="table2"' in page and "<td>28.3</td>" in page


def test_table_ii_readme_block_is_the_papers_layout_with_ours_under_it(tmp_path) -> None:
    """The README's Table II block: the paper's row, then ours (mean [interval]) per version,
    marked ✗ (not bold: the README's bold is the best beyond the noise) where the paper's value
    lies outside; rewritten between its markers only."""
    from dataclasses import replace

    from safl_bench.errors import DataError
    from safl_bench.leaderboard import table2
    from safl_bench.leaderboard.readme import replace_block
    from safl_bench.matching.presets import configure

    def record(method: str, preset: str, seed: int, skill: float) -> object:
        base = scored_record(method, seed=seed, skill=skill, condition="T1R1", source_kind="bev",
                             source_label="KITTI top-view images")
        return replace(base, matcher=configure(preset).to_dict())

    rows = table2.side_by_side([record("sad", "authors-sad", s, 0.99) for s in range(3)])
    sad = next(r for r in rows if r.condition == "T1R1")
    lines = table2.grid(rows).splitlines()
    assert lines[0] == "| Method | Version | Weights | " + " | ".join(table2.CONDITIONS) + " |"
    assert lines[2].startswith("| SAD | paper | | 28.3 | 44.5 |")
    ours = lines[3].split(" | ")
    iv = sad.ours["recall_at_100_precision"]
    assert iv is not None
    expected = iv.format(100.0)
    assert ours[3] == (f"✗ {expected}" if sad.inside("recall_at_100_precision") is False else expected)
    assert "**" not in table2.grid(rows)
    assert ours[4] == "—"  # T5R1 not run
    assert "| BiGAN | paper |" in table2.grid(rows)  # the paper's rows stand without ours
    block = table2.readme_block(rows, "tables/x.md")
    assert "[tables/x.md](leaderboard/tables/x.md)" in block
    assert block.startswith(table2.README_START) and block.endswith(table2.README_END)
    readme = tmp_path / "README.md"
    readme.write_text(f"before\n{table2.README_START}\nold\n{table2.README_END}\nafter\n")
    assert replace_block(readme, table2.README_START, table2.README_END, block, "Table II")
    assert readme.read_text() == f"before\n{block}\nafter\n"
    assert not replace_block(readme, table2.README_START, table2.README_END, block, "Table II")
    readme.write_text(f"{table2.README_END}\n{table2.README_START}\n")
    with pytest.raises(DataError, match="Table II markers"):
        replace_block(readme, table2.README_START, table2.README_END, block, "Table II")


def test_a_method_that_abstains_is_never_marked_best() -> None:
    """Answering only where it is sure (a fifth of the places, all right) gives an AUC near 1
    over its answers; the table shows it but never marks it, and its notes say why."""
    import dataclasses

    import numpy as np

    from safl_bench import metrics
    from safl_bench.leaderboard.tables import ANSWERED_MIN
    from safl_bench.records import mode_result_from_evaluation

    def shy(seed: int) -> ResultRecord:
        truth = task_outcomes(seed, 0.9)
        keep = np.zeros(len(truth.confidence), bool)
        keep[np.flatnonzero(truth.has_true_place)[::5]] = True  # a fifth of the places
        o = metrics.Outcomes(np.where(keep, 5.0, -np.inf), np.where(keep, 1, -1).astype(np.int8),
                             truth.has_true_place, truth.has_candidate, truth.true_rank)
        assert metrics.answered_share(o) is not None and metrics.answered_share(o) < ANSWERED_MIN
        mode = mode_result_from_evaluation(metrics.evaluate_outcomes(o), o)
        return dataclasses.replace(make_record("shy", seed=seed), results={"sequence": mode,
                                                                           "single_frame": mode})

    records = [shy(s) for s in range(3)] + [scored_record(m, seed=s, skill=k) for s in range(3)
                                            for m, k in (("busy", 0.95), ("weak", 0.3))]
    table = _table(records, auc_table)
    (col,) = [j for j, c in enumerate(table.columns) if c == "T1R1"]
    shy_row = table.rows.index(("shy", "1", "sequence"))
    busy_row = table.rows.index(("busy", "1", "sequence"))
    cell = table.cells[shy_row][col]
    assert cell is not None and cell.mean is not None and cell.mean > 0.99  # its AUC: near 1
    assert (shy_row, col) not in table.marks and table.marks.get((busy_row, col)) in ("best", "tied")
    assert any("answered fewer than 50% of the queries with a true place" in n and "shy v1 sequence answered 20%" in n
               for n in table.notes)
