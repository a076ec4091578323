"""Tables that mean what their notes say (issue #37, item 4): each cell of the presets table names
the queries it is scored on, and a time-table cell whose seeds carry one timing shows it as one,
not as an interval of zero width."""

from __future__ import annotations

import dataclasses
from pathlib import Path

from record_factory import make_record

from safl_bench.leaderboard import build_leaderboard
from safl_bench.leaderboard.grouping import table_key
from safl_bench.leaderboard.intervals import without_intervals
from safl_bench.leaderboard.tables import (
    ONE_TIMING,
    QuerySet,
    preset_table,
    query_set,
    recall_table,
    time_table,
)
from safl_bench.matching.presets import configure
from safl_bench.results.records import ResultRecord

N_TASK = 1136  # the task's queries (KITTI 00 top views, every 4th frame)
CONTEXT = 10  # the task's context queries (matched, never scored)


def _scored(record: ResultRecord, preset: str, n_scored: int, positives: int) -> ResultRecord:
    """`record` under matcher `preset`, its task spec and metrics saying how many queries."""
    task = dataclasses.replace(record.task, spec={**record.task.spec, "n_queries": N_TASK,
                                                  "context_queries": CONTEXT})
    results = {mode: dataclasses.replace(result, metrics=dataclasses.replace(
        result.metrics, n_queries=n_scored, n_scored=n_scored, n_positives=positives))
        for mode, result in record.results.items()}
    return dataclasses.replace(record, task=task, matcher=configure(preset).to_dict(), results=results)


def _bev(method: str, condition: str, preset: str, n_scored: int, positives: int,
         recall: float = 0.5, seed: int = 0) -> ResultRecord:
    base = make_record(method, condition=condition, source_kind="bev", task_version=1, seed=seed,
                       source_label="KITTI top-view images", recall=recall)
    return _scored(base, preset, n_scored, positives)


def _rows(markdown: str) -> list[str]:
    return [line for line in markdown.splitlines() if line.startswith("| ") and "---" not in line]


def test_query_set_is_read_from_the_task_spec_and_the_presets_evaluation_settings() -> None:
    # the paper preset: every query but the task's 10 context ones
    paper = _bev("sad", "T1R1", "paper", N_TASK - CONTEXT, 1100)
    assert query_set(paper) == QuerySet(10, 1135, N_TASK, False)
    assert query_set(paper).text == "queries 10–1135 of 1136"  # type: ignore[union-attr]
    # authors: the first 300 frames, 5 trimmed at each end; the context covers the first 5
    authors = _bev("sad", "T1R1", "authors", 285, 280)
    assert query_set(authors) == QuerySet(10, 294, 300, True)
    assert query_set(authors).text == "queries 10–294 of the first 300 frames"  # type: ignore[union-attr]
    # authors-sad: the first 300 frames, 20 trimmed at each end
    assert query_set(_bev("sad", "T1R1", "authors-sad", 260, 250)) == QuerySet(20, 279, 300, True)
    # a record whose own count disagrees is not given a set it was not scored on
    assert query_set(_bev("sad", "T1R1", "authors", 290, 280)) is None


def test_presets_table_names_each_rows_query_set_and_its_note_says_they_differ() -> None:
    """The paper preset scores 1126 queries, the authors' 285 and 260: one column holds all
    three, so each row names its queries and the note gives each set's count; nothing says the
    denominator is the same for every row."""
    records = [
        _bev("sad", "T1R1", "paper", 1126, 1100, recall=0.1),
        _bev("sad", "T1R1", "authors-sad", 260, 250, recall=0.9),
        _bev("stable_afl", "T1R1", "authors", 285, 280, recall=0.8),
        _bev("stable_afl", "T1R1", "paper", 1126, 1100, recall=0.2),
    ]
    with without_intervals():  # the values and labels only (the bold / ≈ rule is tested elsewhere)
        table = preset_table(table_key(records[0]), records)
    md = table.markdown()
    rows = _rows(md)
    assert rows[0] == "| Method | Version | Matcher · scored queries | T1R1 |"
    assert rows[1:] == [
        "| sad | 1 | authors-sad · queries 20–279 of the first 300 frames | 90.0 |",
        "| sad | 1 | paper · queries 10–1135 of 1136 | 10.0 |",
        "| stable_afl | 1 | authors · queries 10–294 of the first 300 frames | 80.0 |",
        "| stable_afl | 1 | paper · queries 10–1135 of 1136 | 20.0 |",
    ]
    note = next(n for n in table.notes if n.startswith("Scored queries"))
    assert note.startswith("Scored queries per preset (not the same across presets")
    assert "authors: queries 10–294 of the first 300 frames, 280 with a true place" in note
    assert "authors-sad: queries 20–279 of the first 300 frames, 250 with a true place" in note
    assert "paper: queries 10–1135 of 1136, 1100 with a true place" in note
    assert "the same for every method" not in md


def test_one_query_set_is_named_once_and_the_built_leaderboards_notes_are_true(tmp_path: Path) -> None:
    paper = [_bev(m, c, "paper", 1126, 1100) for m in ("sad", "stable_afl") for c in ("T1R1", "T5R1")]
    table = recall_table(table_key(paper[0]), paper)
    assert ("Scored queries, the same in every cell and for every method: queries 10–1135 of "
            "1136, 1100 with a true place.") in table.notes
    authors = [_bev(m, c, "authors", 285, 280) for m in ("sad", "stable_afl") for c in ("T1R1", "T5R1")]
    build_leaderboard(paper, tmp_path, figures=False, site=False, preset_records=authors)
    presets = (tmp_path / "tables/kitti-top-view-images/paper-00-v1-presets-recall.md").read_text()
    assert "the same for every method on a task" not in presets
    assert "Scored queries per preset" in presets
    for line in _rows(presets)[1:]:
        assert "· queries 10–" in line


def _timed(method: str, seed: int, ms: float, carried_from: int | None = None,
           condition: str = "T1R1") -> ResultRecord:
    record = make_record(method, seed=seed, ms=ms, condition=condition)
    if carried_from is None:
        return record
    how = (f"{record.timings.how_run}; the cell's timing (describe_ms_per_frame, peak_memory_mb), "
           f"measured at seed {carried_from}")
    return dataclasses.replace(record, timings=dataclasses.replace(record.timings, how_run=how))


def test_a_cell_whose_seeds_carry_one_timing_shows_one_timing_not_a_zero_width_range() -> None:
    records = [_timed("sad", 0, 0.22), *(_timed("sad", s, 0.22, carried_from=0) for s in (1, 2)),
               _timed("bevplace", 0, 150.0), _timed("bevplace", 1, 160.0), _timed("bevplace", 2, 170.0)]
    table = time_table(table_key(records[0]), records)
    md = table.markdown()
    assert _rows(md)[1:] == ["| bevplace | 1 | 160.00 [150.00, 170.00] |",
                             f"| sad | 1 | 0.22 {ONE_TIMING} |"]
    assert "[0.22, 0.22]" not in md
    note = next(n for n in table.notes if "timed once" in n)
    assert note.startswith("1 of 2 cells were timed once for all their seeds")
    assert "measured at seed S" in note and "in 1 of them" not in note
    # the CSV: no bounds for the one timing, and how many timings each cell is
    frame = table.frame().set_index("Method")
    assert frame.loc["sad", "T1R1 low"] == "" and frame.loc["sad", "T1R1 timings"] == "1"
    assert frame.loc["bevplace", "T1R1 low"] == "150.00" and frame.loc["bevplace", "T1R1 timings"] == "3"
    assert "distinct timings" in md.splitlines()[2]


def test_a_cell_of_fewer_timings_than_seeds_is_the_mean_of_its_timings_and_says_how_many() -> None:
    """Seed 0 timed alone, seeds 1-3 in another run that timed seed 1 and carried it: two
    measurements, whose mean is the cell (not 1.0 / 4 + 2.0 * 3 / 4)."""
    records = [_timed("sad", 0, 1.0), _timed("sad", 1, 2.0),
               *(_timed("sad", s, 2.0, carried_from=1) for s in (2, 3))]
    table = time_table(table_key(records[0]), records)
    assert _rows(table.markdown())[1:] == ["| sad | 1 | 1.50 [1.00, 2.00] (2 timings) |"]


def test_equal_timings_that_do_not_say_they_are_carried_are_still_one_and_the_note_says_so() -> None:
    records = [_timed("sad", 0, 0.5), _timed("sad", 1, 0.5)]
    table = time_table(table_key(records[0]), records)
    assert _rows(table.markdown())[1:] == [f"| sad | 1 | 0.50 {ONE_TIMING} |"]
    note = next(n for n in table.notes if "timed once" in n)
    assert "in 1 of them records that do not say so hold the same timing" in note


def test_a_single_seed_table_shows_its_timing_without_a_mark() -> None:
    table = time_table(table_key(_timed("sad", 0, 0.5)), [_timed("sad", 0, 0.5)])
    assert _rows(table.markdown())[1:] == ["| sad | 1 | 0.50 |"]
    assert not any("timed once" in n for n in table.notes)


def test_guide_blocks_are_written_from_the_records_between_their_markers(tmp_path: Path) -> None:
    """`safl-bench leaderboard` rewrites the guides' record-derived tables (`guides.BLOCKS`) as
    it does the README's; the committed guides are checked against a regeneration in
    test_leaderboard.test_committed_tables_are_regenerated_exactly."""
    from safl_bench.leaderboard.guides import BLOCKS, blocks, update_guides

    paper = [make_record(m, condition=c, task_version=5, recall=r, seed=s)
             for m, r in (("sad", 0.2), ("bevplace", 0.9)) for c in ("T1R1", "T5R1") for s in (0, 1)]
    revisit = [make_record(m, protocol="revisit", sequence=q, task_version=4, recall=r, condition=None)
               for m, r in (("sad", 0.6), ("bevplace", 0.8)) for q in ("00", "09")]
    report = build_leaderboard([*paper, *revisit], tmp_path / "lb", figures=False, site=False)
    made = dict((b.name, text) for b, text in blocks(report))
    assert set(made) == {"synthetic-table2", "synthetic-revisit"}  # no Table II records: no summary
    assert "| sad | 1 | 00 | 0.700 / 0.350 | 60.0 / 30.0 |" in made["synthetic-revisit"]
    assert "task version v5" in made["synthetic-table2"]

    guide = tmp_path / "docs/guides/leaderboard.md"
    guide.parent.mkdir(parents=True)
    starts = {b.name: (b.start, b.end) for b in BLOCKS}
    text = "".join(f"before\n{starts[n][0]}\nstale 89.6\n{starts[n][1]}\nafter\n"
                   for n in ("synthetic-table2", "synthetic-revisit"))
    guide.write_text(text)
    untouched = tmp_path / "docs/guides/reproduce-table-ii.md"
    untouched.write_text("no markers\n")
    assert update_guides(tmp_path, report) == [guide]
    written = guide.read_text()
    assert made["synthetic-table2"] in written and made["synthetic-revisit"] in written
    assert "stale 89.6" not in written and written.count("before\n") == 2
    assert update_guides(tmp_path, report) == []  # unchanged
    assert untouched.read_text() == "no markers\n"


def _table2_board(tmp_path: Path) -> Path:
    """A leaderboard whose real-KITTI 00 paper page has Table II side by side: the three
    methods under the authors' presets on the twelve conditions, two seeds each."""
    from record_factory import scored_record

    from safl_bench.leaderboard import table2

    def record(method: str, preset: str, condition: str, seed: int) -> ResultRecord:
        base = scored_record(method, seed=seed, skill=0.6,
                             condition=condition, source_kind="bev", source_label="KITTI top-view images")
        return dataclasses.replace(base, matcher=configure(preset).to_dict())

    paper = [record(m, "paper", c, s) for m in table2.PUBLISHED for c in table2.CONDITIONS for s in (0, 1)]
    authors = [record(m, table2.PRESET_OF[m], c, s)
               for m in table2.PUBLISHED for c in table2.CONDITIONS for s in (0, 1)]
    out = tmp_path / "lb"
    build_leaderboard(paper, out, figures=False, preset_records=authors)
    return out / "site" / "kitti-top-view-images-paper-00-v0.html"


def test_site_shows_table_ii_in_the_papers_layout_readable_at_1400_pixels(tmp_path: Path) -> None:
    """Methods × the twelve conditions, the paper's row above ours, beside the cell-by-cell
    table; in Chromium at 1400 px nothing scrolls sideways (skipped without the browser)."""
    from safl_bench.leaderboard import table2

    page = _table2_board(tmp_path)
    html = page.read_text(encoding="utf-8")
    grid = html[html.index('<table class="t2grid">'):]
    grid = grid[:grid.index("</table>")]
    assert grid.count("paper (Table II)") == 3
    assert "".join(f'<th scope="col">{c}</th>' for c in table2.CONDITIONS) in grid
    assert '<td class="num">28.3</td>' in grid  # the paper's SAD T1R1
    assert grid.count("<tr") == 1 + 3 * 2  # header, then per method its paper row and ours

    from test_site_browser import ARGS, CHROMIUM, _browser_or_skip

    sync_playwright = _browser_or_skip()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=str(CHROMIUM), args=ARGS)
        view = browser.new_page(viewport={"width": 1400, "height": 900})
        view.goto(page.as_uri())
        box = view.locator("table.t2grid").bounding_box()
        assert box is not None and box["x"] >= 0 and box["x"] + box["width"] <= 1400
        assert view.evaluate("document.documentElement.scrollWidth") <= 1400
        browser.close()


def test_all_results_names_each_records_weights_and_derivation() -> None:
    """The long CSV says which weights a record ran (untrained networks named as such) and which
    superseded task's record a derived one keeps the matches of."""
    from dataclasses import replace

    from record_factory import make_record

    from safl_bench.leaderboard.tables import all_results_frame
    from safl_bench.results.records import Derivation, MethodInfo

    plain = make_record("sad", seed=0)
    untrained = replace(make_record("stable_afl", seed=1), method=MethodInfo(
        name="stable_afl", version="2", params={"weights": {"source": "untrained", "seed": 0}}))
    derived = replace(make_record("bigan", seed=2), derived_from=Derivation(
        task="SAFL/Synth00-T1R1-v4", created="2026-12-01T00:00:00Z", note="derived"))
    frame = all_results_frame([plain, untrained, derived]).set_index("method")
    assert frame.loc["stable_afl", "weights"].tolist() == ["untrained", "untrained"]
    assert frame.loc["sad", "weights"].tolist() == ["", ""]
    assert frame.loc["bigan", "derived_from"].tolist() == ["SAFL/Synth00-T1R1-v4"] * 2
    assert frame.loc["sad", "derived_from"].tolist() == ["", ""]
