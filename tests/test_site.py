"""The leaderboard's web pages without a browser: the same cell texts as the Markdown tables,
the headline (real KITTI first) saying what it is, intervals over seeds, a corrupt record named
in one line while the rest is built, a missing figure as a placeholder, the README's headline
block kept true."""

from __future__ import annotations

from pathlib import Path

import pytest
from site_board import BEV_LABEL, write_board
from site_html import markdown_rows, read_page

from safl_bench.cli import main as cli_main
from safl_bench.errors import DataError
from safl_bench.leaderboard import build_leaderboard
from safl_bench.leaderboard.headline import (
    READING,
    README_END,
    README_START,
    readme_block,
    update_readme,
)
from safl_bench.leaderboard.site import page_file, write_site
from safl_bench.records import load_records

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def board(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = write_board(tmp_path_factory.mktemp("site"))
    assert cli_main(["leaderboard", "--out", str(out), "--no-figures"]) == 0
    return out


def test_every_page_prints_the_markdown_tables_cells(board: Path) -> None:
    pages = sorted((board / "site").glob("*.html"))
    assert {p.name for p in pages} >= {"index.html", "all.html"}
    seen = set()
    for page in pages:
        for section in read_page(page.read_text(encoding="utf-8")).sections:
            header, rows = markdown_rows((board / section.md).read_text(encoding="utf-8"))
            assert section.header == header, (page.name, section.md)
            assert section.rows == rows, (page.name, section.md)
            seen.add(section.md)
    made = {p.relative_to(board).as_posix() for p in (board / "tables").rglob("*.md")}
    assert seen == made  # every Markdown table is on the site


def test_headline_is_real_kitti_and_says_what_it_is(board: Path) -> None:
    index = (board / "index.md").read_text(encoding="utf-8")
    headline = index.split("## Headline", 1)[1].split("\n## ", 1)[0]
    for fact in (f"Source: {BEV_LABEL}", "Sequences: 00, 02", "Protocol: revisit",
                 "Matcher preset: paper", "Seeds: 0, 1", READING):
        assert fact in headline
    assert f"{BEV_LABEL}, revisit protocol" in headline
    page = (board / "site" / "index.html").read_text(encoding="utf-8")
    first = read_page(page).sections[0]
    assert first.source == BEV_LABEL and first.protocol == "revisit"
    assert "Recall at 100 % precision counts the true places found" in page
    for name in ("Source", "Protocol", "Matcher preset", "Seeds"):
        assert f"<dt>{name}</dt>" in page


def test_cells_show_their_interval_and_bold_only_beyond_the_noise(tmp_path: Path) -> None:
    import dataclasses

    from record_factory import scored_record

    from safl_bench.matcher_presets import configure

    paper = configure("paper").to_dict()
    records = [dataclasses.replace(scored_record(m, seed=s, skill=k, condition="T1R1"), matcher=paper)
               for m, k in (("strong", 0.95), ("weak", 0.3)) for s in (0, 1)]
    report = build_leaderboard(records, tmp_path / "lb", figures=False)
    published = next(p for p in report.tables if p.table.title.startswith("Recall@1"))
    table = published.table
    strong = table.rows.index(("strong", "1", "sequence"))
    cell, fmt = table.cells[strong][0], table.formats[0]
    assert cell is not None and cell.low is not None and table.marks[(strong, 0)] == "best"
    page = (tmp_path / "lb" / "site" / f"{page_file(published.key)}").read_text(encoding="utf-8")
    html = page.split("Recall@1 (%)")[1]  # the Recall@1 table's section
    assert f"<strong>{fmt.number(cell.mean)}</strong>" in html
    assert f'<span class="interval">[{fmt.number(cell.low)}, {fmt.number(cell.high)}]</span>' in html


def test_a_corrupt_record_is_named_in_one_line_and_the_rest_is_built(tmp_path: Path, capsys) -> None:
    out = write_board(tmp_path)
    bad = out / "records" / "broken@1" / "SAFL__BEVKITTI00-Revisit-v0" / "seed-0.json"
    bad.parent.mkdir(parents=True)
    bad.write_text('{"schema": 1, "method": ')
    assert cli_main(["leaderboard", "--out", str(out), "--no-figures"]) == 2  # built from the rest
    lines = [line for line in capsys.readouterr().err.splitlines() if str(bad) in line]
    assert len(lines) == 1 and "not valid JSON" in lines[0]
    page = read_page((out / "site" / "index.html").read_text(encoding="utf-8"))
    assert page.sections[0].rows  # built from the rest
    text = (out / "site" / "index.html").read_text(encoding="utf-8")
    assert "broken@1/SAFL__BEVKITTI00-Revisit-v0/seed-0.json: not valid JSON" in text


def test_a_missing_figure_is_a_visible_placeholder(tmp_path: Path) -> None:
    out = write_board(tmp_path)
    records, _ = load_records(out / "records")
    report = build_leaderboard(records, out)
    rel = next(rel for links in report.figure_links.values() for _, rel in links
               if rel.endswith("revisit-v0-pr.png"))
    page = (out / "site" / "index.html").read_text(encoding="utf-8")
    assert f'src="../{rel}"' in page and "placeholder" not in read_page(page).placeholders
    (out / rel).unlink()
    write_site(report)
    placeholders = read_page((out / "site" / "index.html").read_text(encoding="utf-8")).placeholders
    assert any(rel in p and "safl-bench leaderboard" in p for p in placeholders)


def test_regeneration_is_byte_identical_and_removes_stale_pages(board: Path) -> None:
    first = {p: p.read_bytes() for p in (board / "site").glob("*.html")}
    stale = board / "site" / "gone.html"
    stale.write_text("old")
    assert cli_main(["leaderboard", "--out", str(board), "--no-figures"]) == 0
    assert not stale.exists()
    assert {p: p.read_bytes() for p in (board / "site").glob("*.html")} == first


def test_readme_block_is_rewritten_between_its_markers(board: Path, tmp_path: Path) -> None:
    records, _ = load_records(board / "records")
    report = build_leaderboard(records, tmp_path / "lb", figures=False, site=False)
    assert report.headline is not None
    readme = tmp_path / "README.md"
    readme.write_text(f"# x\n\nbefore\n\n{README_START}\nold\n{README_END}\n\nafter\n")
    assert update_readme(readme, report.headline, report.headline_records)
    text = readme.read_text()
    assert text.startswith("# x\n\nbefore\n\n") and text.endswith("\n\nafter\n")
    assert "| sad | 1 | sequence | ≈ 0.780 |" in text and "Matcher preset (all rows)" not in text
    assert not update_readme(readme, report.headline, report.headline_records)  # unchanged
    plain = tmp_path / "PLAIN.md"
    plain.write_text("no markers\n")
    assert not update_readme(plain, report.headline, report.headline_records)
    broken = tmp_path / "BROKEN.md"
    broken.write_text(f"{README_START}\nno end\n")
    with pytest.raises(DataError, match=r"BROKEN\.md"):
        update_readme(broken, report.headline, report.headline_records)


def test_committed_readme_headline_is_what_the_records_give(tmp_path: Path) -> None:
    records, _ = load_records(REPO / "leaderboard" / "records")
    if not records:
        pytest.skip("no committed records in leaderboard/records yet")
    from safl_bench.cli.leaderboard import load_preset_records

    presets, _ = load_preset_records(REPO / "leaderboard")
    report = build_leaderboard(records, tmp_path, figures=False, site=False, preset_records=presets)
    assert report.headline is not None and report.headline.key.source_kind == "bev"
    block = readme_block(report.headline, report.headline_records,
                         "`leaderboard/site/index.html` (open it from disk) and "
                         "[leaderboard/index.md](leaderboard/index.md)")
    assert block in (REPO / "README.md").read_text(encoding="utf-8"), (
        "README.md's headline block is stale: run `safl-bench leaderboard` at the checkout's root")
