"""The leaderboard as a static web site: `<leaderboard>/site/`, opened from disk, no server.

Written by `safl-bench leaderboard` from the `BuildReport` of the same regeneration, so every
table is the very `Table` its Markdown file was printed from and every cell shows the text the
Markdown shows (`Table.cell_text`, bold and "≈" where the Markdown has them). Pages:

    site/index.html             the headline (real KITTI when there are records of it): what it
                                is (source, protocol, matcher preset, seeds), how to read it, the
                                table, the measures beside it and the figures of its table group
    site/<source>-<stem>.html   one page per table group (source, protocol, sequence, version):
                                its tables with their figures beside them
    site/all.html               every table on one page, to filter across sources and protocols

Every page carries its CSS and JavaScript inline (no CDN, no network): columns sort on a click
on their header; rows filter by source, protocol, matcher preset and method (the choice is kept
in the address's `#fragment`, so a filtered page can be bookmarked); each cell's tooltip names
the records behind it, and a click opens a detail view with each seed's value, the record file,
when and where it was made, and the `safl-bench explain` command that draws the cell. Where a
cell shows its mean and, under it, its 95 % interval over seeds and queries; bold is best beyond
the noise and "≈" tied for best, as in the Markdown (`leaderboard.intervals`).
Which record gives which cell is found by calling the table's own builder on one record at a
time (`PublishedTable.rebuild`), never by reading column names. A figure that is missing when
the site is written, or later, shows a placeholder naming the file and the command that draws it.
"""

from __future__ import annotations

import html
import json
import os
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

from safl_bench.common.atomic import atomic_write_text
from safl_bench.leaderboard import table2
from safl_bench.leaderboard.grouping import TableKey, slugify
from safl_bench.leaderboard.headline import READING, facts
from safl_bench.leaderboard.intervals import BEST, TIED, without_intervals
from safl_bench.leaderboard.report import BuildReport, PublishedTable, headline_rank
from safl_bench.leaderboard.tables import RowKey, Table, ValueFormat, seeds_sentence
from safl_bench.results.records import Problem, ResultRecord, record_path
from safl_bench.sources import root_options

SITE_DIR = "site"
INDEX = "index.html"
ALL = "all.html"
RANKING = "ranking.html"
SCALING = "speed.html"
#: The anchor of a page's loop-closure section (its navigation entry links to it).
SLAM_ID = "loop-closure"
#: The image-fidelity figure `safl-bench data fidelity --out` writes beside the board (it needs
#: real KITTI's images, so the build shows it when it is there and never draws it).
FIDELITY_PNG = "fidelity/fidelity.png"
#: What a figure needs when it is missing: the command that draws it.
DRAW_FIGURES = "safl-bench leaderboard"

#: Where a record's file is shown to live (for the detail view and the explain command): its
#: records folder as the reader names it, e.g. "leaderboard/records".
RecordFolder = Callable[[ResultRecord], str]


class _Registry:
    """The records a page's cells come from, listed once per page (cells refer to them by index)."""

    def __init__(self, folder: RecordFolder) -> None:
        self.folder = folder
        self.items: list[dict[str, object]] = []
        self._index: dict[int, int] = {}

    def ref(self, record: ResultRecord) -> int:
        if id(record) not in self._index:
            where = self.folder(record)
            path = record_path(where, record.method.name, record.method.version, record.task.id,
                               record.seed).as_posix()
            self._index[id(record)] = len(self.items)
            self.items.append({
                "seed": record.seed,
                "task": record.task.id,
                "record": path,
                "created": record.created,
                "git": record.environment.git_revision,
                "cpu": f"{record.environment.cpu_model} ({record.environment.cpu_cores} cores)",
                "how_run": record.timings.how_run,
                "preset": _preset(record),
                "explain": explain_command(record, where),
            })
        return self._index[id(record)]

    def script(self) -> str:
        data = json.dumps(self.items, sort_keys=True, ensure_ascii=False).replace("</", "<\\/")
        return f'<script type="application/json" id="lb-records">{data}</script>'


@dataclass
class _Page:
    file: str
    title: str
    key: TableKey | None
    tables: list[PublishedTable]


def default_records_folder(preset_records: Sequence[ResultRecord] = ()) -> RecordFolder:
    """The committed layout: leaderboard/records, and leaderboard/preset-records/<preset> for
    `preset_records` (the records of other matcher presets)."""
    presets = {id(r) for r in preset_records}

    def folder(record: ResultRecord) -> str:
        if id(record) in presets:
            return f"leaderboard/preset-records/{_preset(record)}"
        return "leaderboard/records"

    return folder


def page_file(key: TableKey) -> str:
    """The page of a table group, e.g. 'kitti-top-view-images-revisit-v0.html'."""
    return f"{key.source_slug}-{key.stem}.html"


def write_site(
    report: BuildReport,
    *,
    records_folder: RecordFolder | None = None,
    problems: Sequence[Problem] = (),
    problem_base: str | os.PathLike[str] | None = None,
) -> list[Path]:
    """Write the site for `report` into `report.out_dir / "site"`; returns the files written.

    `records_folder(record)` names the folder a record was read from (default:
    `default_records_folder()`, leaderboard/records). `problems`: record files that could not be used; each
    is named on every page, relative to `problem_base` when given.
    """
    out = Path(report.out_dir)
    site = out / SITE_DIR
    folder = records_folder or default_records_folder()
    groups: dict[TableKey, list[PublishedTable]] = defaultdict(list)
    for published in report.tables:
        groups[published.key].append(published)
    order = sorted(groups, key=headline_rank)
    pages = [_Page(page_file(k), k.caption, k, groups[k]) for k in order]
    nav = [(INDEX, "Headline"), *((p.file, p.title) for p in pages), (ALL, "All tables")]
    if report.ranking:
        nav.insert(1, (RANKING, "Synthetic vs real KITTI"))
    # the sections a reader looks for by name get their own entries, before "All tables"
    for page in pages:
        if page.key is not None and page.key in report.table2:
            nav.insert(len(nav) - 1, (f"{page.file}#table2-{slugify(page.key.stem)}",
                                      f"Table II ({page.key.source_label})"))
    for page in pages:
        if page.key is not None and _slam_section(out, page.key):
            nav.insert(len(nav) - 1, (f"{page.file}#{SLAM_ID}",
                                      f"Loop closure in SLAM ({page.key.source_label})"))
    if report.scaling:
        nav.insert(len(nav) - 1, (SCALING, "Matcher speed"))
    skipped = [_problem_line(p, problem_base) for p in problems]
    written: list[Path] = []

    def emit(name: str, make: Callable[[_Registry], str], title: str,
             tables: list[PublishedTable]) -> None:
        registry = _Registry(folder)
        body = make(registry)
        text = _document(title, name, nav, skipped, body, tables, registry)
        path = site / name
        if not (path.is_file() and path.read_text(encoding="utf-8") == text):
            atomic_write_text(path, text)
        written.append(path)

    head = _headline_tables(report)
    emit(INDEX, lambda reg: _headline_body(report, head, out, reg), "Headline", head)
    for page in pages:
        figures = report.figure_links.get(page.key, []) if page.key else []

        def body(reg: _Registry, page: _Page = page, figures: list[tuple[str, str]] = figures) -> str:
            return f"<h1>{_e(page.title)}</h1>" + "".join(
                _table_section(t, out, reg, figures=figures if i == 0 else ())
                for i, t in enumerate(page.tables)) + _table2_section(report, page.key) + _slam_section(
                    out, page.key)

        emit(page.file, body, page.title, page.tables)
    if report.ranking:
        emit(RANKING, lambda reg: _ranking_body(report, out), "Synthetic vs real KITTI", [])
    if report.scaling:
        emit(SCALING, lambda reg: _scaling_body(report, out), "Matcher speed", [])
    every = [t for page in pages for t in page.tables]
    emit(ALL, lambda reg: "<h1>All tables</h1>" + "".join(_table_section(t, out, reg) for t in every),
         "All tables", every)
    return written


# --------------------------------------------------------------------------------------------
# Page parts


def _headline_tables(report: BuildReport) -> list[PublishedTable]:
    """The headline's PublishedTable and those of the measures shown beside it, in that order."""
    wanted = [t for t in (report.headline, *report.headline_robust) if t is not None]
    by_id = {id(p.table): p for p in report.tables}
    return [by_id[id(t)] for t in wanted if id(t) in by_id]


def _headline_body(report: BuildReport, head: list[PublishedTable], out: Path,
                   registry: _Registry) -> str:
    if not head or report.headline is None:
        return "<h1>Headline</h1><p>No table to show.</p>"
    table = report.headline
    items = "".join(f"<div><dt>{_e(name)}</dt><dd>{_e(value)}</dd></div>"
                    for name, value in facts(table, report.headline_records))
    parts = [
        f"<h1>Headline: {_e(table.title)}</h1>",
        f'<dl class="facts" id="headline-facts">{items}</dl>',
        f'<p class="reading" id="reading">{_inline_code(READING)}</p>',
    ]
    figures = report.figure_links.get(table.key, [])
    parts += [_table_section(p, out, registry, figures=figures if i == 0 else (), headline=i == 0)
              for i, p in enumerate(head)]
    if report.training_figures:
        figs = "".join(_figure(out, rel, f"Training stability: {source} ({', '.join(methods)})")
                       for source, rel, methods in report.training_figures)
        parts.append(f'<section class="training"><h2>Training stability (Figure 14)</h2>'
                     f'<div class="figures">{figs}</div></section>')
    return "".join(parts)


def _table_section(published: PublishedTable, out: Path, registry: _Registry, *,
                   figures: Sequence[tuple[str, str]] = (), headline: bool = False) -> str:
    """One table as a section: heading, seeds, the sortable table, `figures` beside it, notes."""
    table = published.table
    key = table.key
    sid = _table_id(published)
    provenance = _provenance(published)
    marks = table.marks
    show = [(i, h) for i, h in enumerate(table.row_header) if h]
    groups = column_groups(table.columns)
    head = "".join(f'<th data-type="text" scope="col">{_e(h)}</th>' for _, h in show)
    head += "".join(f'<th data-type="num" scope="col"{_group_attr(g)}>{_e(c)}</th>'
                    for c, g in zip(table.columns, groups or [""] * len(table.columns),
                                    strict=True))
    rows = []
    for i, row in enumerate(table.rows):
        recs = [r for j in range(len(table.columns)) for r, _ in provenance.get((row, j), [])]
        presets = sorted({_preset(r) for r in recs})
        attrs = {
            "data-method": row[0],
            "data-version": row[1],
            "data-row": row[2],
            "data-presets": " ".join(presets),
        }
        cells = "".join(f"<td>{_e(row[k])}</td>" for k, _ in show)
        for j, fmt in enumerate(table.formats):
            cells += _cell(table, i, j, fmt, marks.get((i, j)), provenance.get((row, j), []), registry)
        rows.append(f"<tr {_attrs(attrs)}>{cells}</tr>")
    notes = "".join(f"<li>{_inline_code(n)}</li>" for n in table.notes)
    beside = ('<aside class="figures">' + "".join(_figure(out, rel, label) for label, rel in figures)
              + "</aside>") if figures else ""
    md_link = f'<a class="source-md" href="../{_e(published.md)}">Markdown</a>'
    csv = published.md[:-3] + ".csv"
    section_attrs = {
        "class": "lb-table" + (" headline" if headline else ""),
        "id": sid,
        "data-source": key.source_label,
        "data-protocol": key.protocol,
    }
    return (
        f"<section {_attrs(section_attrs)}>"
        f"<h2>{_e(table.heading)}</h2>"
        f'<p class="meta">{_e(seeds_sentence(table).replace("**Bold**", "Bold"))} · {md_link} · '
        f'<a href="../{_e(csv)}">CSV</a>{_group_picker(groups)}</p>'
        f'<div class="body"><div class="scroll"><table class="sortable">'
        f"<thead><tr>{head}</tr></thead><tbody>{''.join(rows)}</tbody></table></div>{beside}</div>"
        f'<p class="shown" aria-live="polite"></p>'
        + (f'<ul class="notes">{notes}</ul>' if notes else "")
        + "</section>"
    )


def _table2_section(report: BuildReport, key: TableKey | None) -> str:
    """The paper's Table II beside ours (`table2`), on the page of its table group; '' if none."""
    if key is None or key not in report.table2:
        return ""
    rows, md = report.table2[key]
    head = "".join(f'<th scope="col">{_e(h)}</th>' for h in table2.header())
    body = "".join(
        "<tr>" + "".join(f'<td class="outside">{_e(c)}</td>' if h == "inside" and c == "no"
                         else f"<td>{_e(c)}</td>" for h, c in zip(table2.header(), table2.cells(row), strict=True))
        + "</tr>" for row in rows)
    summary = "".join(f"<li>{_inline_code(line)}</li>" for line in table2.summary(rows))
    order, why = report.table2_notes.get(key, ([], []))
    extra = "".join(f"<h3>{_e(title)}</h3><ul class=\"notes\">{''.join(f'<li>{_inline_code(x)}</li>' for x in lines)}</ul>"
                    for title, lines in (("The paper's order (Stable-AFL > BiGAN > SAD), our measure", order),
                                         ("What each cell outside its interval gives under the changes measured", why))
                    if lines)
    return (f'<section class="table2" id="table2-{_e(slugify(key.stem))}">'
            f"<h2>{_e(table2.TITLE)}</h2><p>{_inline_code(table2.INTRO)}</p>"
            f'<p class="meta"><a class="source-md" href="../{_e(md)}">Markdown</a> · '
            f'<a href="../{_e(md[:-3] + ".csv")}">CSV</a></p>'
            + _table2_grid(rows) +
            f'<h3>Cell by cell, both measures</h3><div class="scroll"><table><thead><tr>{head}</tr></thead>'
            f'<tbody>{body}</tbody></table></div><ul class="notes">{summary}</ul>{extra}</section>')


def _table2_grid(rows: Sequence[table2.Row]) -> str:
    """Table II in the paper's own layout (`table2.grid`, the README's): methods × the twelve
    conditions, the paper's row and under it each row of ours (version, weights), our mean over
    the interval; a value whose interval misses the paper's is marked. Narrow enough for a
    1400-pixel window without scrolling sideways (labels wrap, intervals under the means)."""
    measure, title = table2.MEASURES[0]
    groups: dict[tuple[str, str, str], dict[str, table2.Row]] = {}
    for row in rows:
        groups.setdefault((row.method, row.version, row.weights), {})[row.condition] = row
    head = ('<th scope="col">Method</th><th scope="col">Row</th>'
            + "".join(f'<th scope="col">{_e(c)}</th>' for c in table2.CONDITIONS))
    body = []
    for name in table2.PUBLISHED:
        ours = [(k, v) for k, v in groups.items() if k[0] == name]
        paper = "".join(f'<td class="num">{table2.PUBLISHED[name][c]:.1f}</td>' for c in table2.CONDITIONS)
        body.append(f'<tr class="paper"><th scope="row" rowspan="{1 + len(ours)}">'
                    f"{_e(table2.PAPER_NAMES[name])}</th><td class=\"who\">paper (Table II)</td>{paper}</tr>")
        for (_, version, weights), by_condition in ours:
            cells = []
            for condition in table2.CONDITIONS:
                cell = by_condition.get(condition)
                iv = cell.ours.get(measure) if cell is not None else None
                if cell is None or iv is None:
                    cells.append('<td class="num">—</td>')
                    continue
                outside = cell.inside(measure) is False
                cls = "num outside" if outside else "num"
                tip = (f"paper {cell.paper:.1f}; ours {iv.format(100.0)}: the paper's value lies "
                       f"{'outside' if outside else 'inside'} our interval")
                cells.append(f'<td class="{cls}" title="{_e(tip)}">{iv.mean * 100:.1f}'
                             f'<span class="interval">[{iv.low * 100:.1f}, {iv.high * 100:.1f}]</span></td>')
            body.append(f'<tr><td class="who">@{_e(version)} · {_e(weights)}</td>{"".join(cells)}</tr>')
    return (f"<h3>In the paper's layout: {_e(title)}</h3>"
            "<p class=\"meta\">Each method: the paper's row, then ours (mean over the seeds, its 95 % "
            "interval under it); red: the paper's value lies outside our interval.</p>"
            f'<table class="t2grid"><thead><tr>{head}</tr></thead><tbody>{"".join(body)}</tbody></table>')


def _cell(table: Table, i: int, j: int, fmt: ValueFormat, mark: str | None,
          sources: list[tuple[ResultRecord, float | None]], registry: _Registry) -> str:
    cell = table.cells[i][j]
    text = table.value_text(cell, fmt)
    shown = (f"<strong>{_e(text)}</strong>" if mark == BEST else
             f'<span class="tied" title="tied for best">≈ {_e(text)}</span>' if mark == TIED else _e(text))
    attrs: dict[str, str] = {"class": "cell"}
    if cell is not None and cell.mean is not None:
        attrs["data-value"] = fmt.number(cell.mean)
    interval = ""
    bracket = table.interval_text(cell, fmt)
    if bracket:
        interval = f'<span class="interval">{_e(bracket)}</span>'
    if cell is not None and cell.low is not None and cell.high is not None:
        attrs["data-interval"] = f"{fmt.number(cell.low)} {fmt.number(cell.high)}"
    text = table.cell_text(cell, fmt)
    row = table.rows[i]
    where = " ".join(v for v, h in zip(row, table.row_header, strict=True) if h)
    if sources:
        ordered = sorted(sources, key=lambda rv: (rv[0].seed, rv[0].task.id, _preset(rv[0])))
        attrs["data-src"] = " ".join(
            f"{registry.ref(r)}:{'n/a' if v is None else fmt.number(v)}" for r, v in ordered)
        seeds = ", ".join(str(r.seed) for r, _ in ordered)
        attrs["title"] = (f"{where} · {table.columns[j]}: {text} (seed {seeds}); click for the "
                          "record, its provenance and the explain command")
        attrs["tabindex"] = "0"
    else:
        attrs["title"] = f"{where} · {table.columns[j]}: not run (no record)"
    return f'<td {_attrs(attrs)}><span class="v">{shown}</span>{interval}</td>'


def explain_command(record: ResultRecord, records_folder: str) -> str:
    """The `safl-bench explain` command that draws `record`'s cell."""
    from safl_bench.methods.method import method_selector

    method = method_selector(record.method.name, record.method.version,  # the record's version
                             record.task.source_kind)
    parts = ["safl-bench explain", f"--method {method}", f"--task {record.task.id}",
             f"--seed {record.seed}", f"--results {records_folder}"]
    roots = root_options(record.task.source_kind, record.task.spec.get("rotated"))
    if roots:
        parts.append(roots)
    return " ".join(parts)


def _provenance(published: PublishedTable) -> dict[tuple[RowKey, int], list[tuple[ResultRecord, float | None]]]:
    """Per (row, column index) the records (and each one's value) the cell was made from."""
    table = published.table
    columns = {c: j for j, c in enumerate(table.columns)}
    rows = set(table.rows)
    out: dict[tuple[RowKey, int], list[tuple[ResultRecord, float | None]]] = defaultdict(list)
    for record in published.records:
        with without_intervals():  # each record's values only: no bootstrap per record
            alone = published.rebuild([record])
        for i, row in enumerate(alone.rows):
            if row not in rows:
                continue
            for j, column in enumerate(alone.columns):
                cell = alone.cells[i][j]
                if cell is not None and column in columns:
                    out[(row, columns[column])].append((record, cell.mean))
    return out


def _preset(record: ResultRecord) -> str:
    from safl_bench.matching.presets import label

    return label(record.matcher)


def column_groups(columns: Sequence[str]) -> list[str]:
    """The sequence each column belongs to ("00 F1max" -> "00"), when a table's columns come in
    two or more such groups (a table over several sequences, wider than a page); else []."""
    heads = [c.split(" ", 1)[0] for c in columns]
    if not heads or not all(h.isdigit() and " " in c for h, c in zip(heads, columns, strict=True)):
        return []
    return heads if len(set(heads)) > 1 else []


def _group_attr(group: str) -> str:
    return f' data-group="{_e(group)}"' if group else ""


def _group_picker(groups: Sequence[str]) -> str:
    """The 'Sequence' picker of a table whose columns come in groups: one group at a time (the
    first by default, so the table fits the page), or all of them."""
    if not groups:
        return ""
    options = "".join(f'<option value="{_e(g)}">{_e(g)}</option>' for g in dict.fromkeys(groups))
    return (f' · <label>Sequence <select class="colgroup">{options}'
            '<option value="">all (wide)</option></select></label>')


def _table_id(published: PublishedTable) -> str:
    return slugify(published.md.removeprefix("tables/").removesuffix(".md"))


def _figure(out: Path, rel: str, label: str) -> str:
    missing = _e(f"Figure not drawn: {rel}. Draw it with `{DRAW_FIGURES}` (without --no-figures).")
    if not (out / rel).is_file():
        return f'<figure class="missing"><div class="placeholder">{missing}</div><figcaption>{_e(label)}</figcaption></figure>'
    return (f'<figure><a href="../{_e(rel)}"><img src="../{_e(rel)}" alt="{_e(label)}" '
            f'data-missing="{missing}"></a><figcaption>{_e(label)}</figcaption></figure>')


def _problem_line(problem: Problem, base: str | os.PathLike[str] | None) -> str:
    path = problem.path
    if base is not None:
        try:
            path = Path(path).relative_to(base)
        except ValueError:
            pass
    return f"{path}: {problem.reason}"


def _document(title: str, name: str, nav: list[tuple[str, str]], skipped: list[str], body: str,
              tables: list[PublishedTable], registry: _Registry) -> str:
    current = ' aria-current="page" class="current"'
    links = "".join(f'<a href="{_e(f)}"{current if f == name else ""}'
                    f'{_anchor_attr(f)}>{_e(t)}</a>' for f, t in nav)
    sources = sorted({t.key.source_label for t in tables})
    protocols = sorted({t.key.protocol for t in tables})
    methods = sorted({row[0] for t in tables for row in t.table.rows})
    presets = sorted({_preset(r) for t in tables for r in t.records})
    banner = ""
    if skipped:
        items = "".join(f"<li><code>{_e(s)}</code></li>" for s in skipped)
        banner = (f'<div class="problems" role="alert"><strong>Skipped record files</strong> '
                  f"(not used; rerun their cells with <code>safl-bench run</code>):<ul>{items}</ul></div>")
    filters = (
        '<form class="filters" id="filters" onsubmit="return false">'
        + _select("source", "Source", sources)
        + _select("protocol", "Protocol", protocols)
        + _select("preset", "Matcher preset", presets)
        + _select("method", "Method", methods)
        + '<button type="button" id="f-reset">Show all</button></form>'
    )
    return (
        "<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
        "<meta name=\"viewport\" content=\"width=device-width, initial-scale=1\">"
        f"<title>{_e(title)} — safl-bench leaderboard</title><style>{_CSS}</style></head>"
        f"<body><header><div class=\"brand\">safl-bench leaderboard</div><nav>{links}</nav></header>"
        f"{banner}{filters}<main>{body}</main>"
        '<dialog id="detail"><form method="dialog"><button class="close" aria-label="close">×</button></form>'
        '<div id="detail-body"></div></dialog>'
        "<footer>Regenerated by <code>safl-bench leaderboard</code> from the result records; "
        "the same numbers as the Markdown tables beside it. Sort: click a column header. "
        "A cell's records: hover or click it.</footer>"
        f"{registry.script()}<script>{_JS}</script></body></html>\n"
    )


def _anchor_attr(href: str) -> str:
    """A navigation link to a section keeps its anchor when the filters rewrite the links."""
    return f' data-anchor="#{_e(href.split("#", 1)[1])}"' if "#" in href else ""


def _select(name: str, label: str, values: list[str]) -> str:
    options = '<option value="">all</option>' + "".join(
        f'<option value="{_e(v)}">{_e(v)}</option>' for v in values)
    return f'<label>{_e(label)} <select id="f-{name}" data-filter="{name}">{options}</select></label>'


def _attrs(attrs: dict[str, str]) -> str:
    return " ".join(f'{k}="{html.escape(v, quote=True)}"' for k, v in attrs.items())


def _ranking_body(report: BuildReport, out: Path) -> str:
    """The synthetic-against-real ranking page (`ranking`): the summary table, its notes, the
    figure, and the image-fidelity figure when `data fidelity` wrote one beside the board."""
    from safl_bench.leaderboard import ranking

    rows = ranking.summary_rows(report.ranking)
    head = "".join(f"<th>{_e(c)}</th>" for c in rows[0])
    body = "".join("<tr>" + "".join(f"<td>{_e(c)}</td>" for c in r) + "</tr>" for r in rows[1:])
    notes = "".join(f"<li>{_inline_code(n)}</li>" for n in ranking.notes(report.ranking))
    figs = ""
    if report.ranking_figure:
        figs += _figure(out, report.ranking_figure, "Recall@1 per method, synthetic 00 against real 00")
    if (out / FIDELITY_PNG).is_file():
        figs += _figure(out, FIDELITY_PNG, "Image statistics and difficulty curves, synthetic 00 "
                        "against real KITTI (`safl-bench data fidelity`)")
    return (f"<h1>{_e(ranking.TITLE)}</h1><p>{_inline_code(ranking.INTRO)}</p>"
            f'<section id="ranking"><div class="scroll"><table><thead><tr>{head}</tr></thead>'
            f"<tbody>{body}</tbody></table></div><ul>{notes}</ul>"
            f'<div class="figures">{figs}</div></section>')


def _scaling_body(report: BuildReport, out: Path) -> str:
    """The matcher's speed page (`scaling`): the runs' table and the curve."""
    from safl_bench.leaderboard import scaling

    rows = scaling.rows(report.scaling)
    head = "".join(f"<th>{_e(c)}</th>" for c in rows[0])
    body = "".join("<tr>" + "".join(f"<td>{_inline_code(c)}</td>" for c in r) + "</tr>"
                   for r in rows[1:])
    figs = (_figure(out, report.scaling_figure, "Time and peak memory against frames")
            if report.scaling_figure else "")
    return (f"<h1>{_e(scaling.TITLE)}</h1><p>{_inline_code(scaling.INTRO)}</p>"
            f'<section id="scaling"><div class="figures">{figs}</div><div class="scroll"><table>'
            f"<thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div></section>")


def _slam_section(out: Path, key: TableKey | None) -> str:
    """The loop-closure table the build wrote for this revisit group, if any
    (`slam_table`: tables/<source>/<stem>-slam.md)."""
    if key is None:
        return ""
    path = out / "tables" / key.source_slug / f"{key.stem}-slam.md"
    if not path.is_file():
        return ""
    from safl_bench.leaderboard.slam_table import slam_html

    body = slam_html(path.read_text(encoding="utf-8"))
    return f'<section class="slam" id="{SLAM_ID}">{body}</section>'


def _e(text: object) -> str:
    return html.escape(str(text), quote=True)


def _inline_code(text: str) -> str:
    """Escape `text` and show its `backticked` parts as code."""
    parts = _e(text).split("`")
    return "".join(f"<code>{p}</code>" if k % 2 else p for k, p in enumerate(parts))


_CSS = """
:root{--fg:#1b1f24;--muted:#57606a;--line:#d0d7de;--bg:#fff;--head:#f6f8fa;--accent:#0969da;--bad:#cf222e}
*{box-sizing:border-box}body{margin:0;font:14px/1.45 system-ui,-apple-system,"Segoe UI",Roboto,sans-serif;color:var(--fg);background:var(--bg)}
header{display:flex;flex-wrap:wrap;gap:.4rem 1.2rem;align-items:center;padding:.6rem 1.2rem;background:#24292f;color:#fff}
header .brand{font-weight:700;font-size:1.05rem}header nav{display:flex;flex-wrap:wrap;gap:.2rem .9rem}
header a{color:#c9d1d9;text-decoration:none}header a.current{color:#fff;font-weight:600;border-bottom:2px solid #fff}
main{padding:0 1.2rem 2rem}h1{font-size:1.35rem;margin:1rem 0 .6rem}h2{font-size:1.05rem;margin:1.4rem 0 .3rem}
.facts{display:flex;flex-wrap:wrap;gap:.5rem;margin:.4rem 0}.facts div{border:1px solid var(--line);border-radius:6px;padding:.25rem .6rem;background:var(--head)}
.facts dt{font-size:.72rem;text-transform:uppercase;color:var(--muted)}.facts dd{margin:0;font-weight:600}
.reading{max-width:70rem;border-left:4px solid var(--accent);padding:.4rem .8rem;background:#f0f6ff;margin:.6rem 0}
.filters{display:flex;flex-wrap:wrap;gap:.5rem 1rem;align-items:center;padding:.6rem 1.2rem;border-bottom:1px solid var(--line);background:var(--head);position:sticky;top:0;z-index:2}
.filters select{font:inherit;padding:.1rem .3rem}.meta{color:var(--muted);margin:.1rem 0 .4rem}
.body{display:flex;flex-direction:column;gap:1rem;align-items:flex-start}.scroll{overflow-x:auto;max-width:100%}
table{border-collapse:collapse;font-variant-numeric:tabular-nums}th,td{border:1px solid var(--line);padding:.2rem .5rem;white-space:nowrap}
th{background:var(--head);cursor:pointer;user-select:none;position:relative}th[data-type=num],td.cell{text-align:right}
th[aria-sort=ascending]::after{content:" ▲";font-size:.7em}th[aria-sort=descending]::after{content:" ▼";font-size:.7em}
tbody tr:nth-child(even){background:#fafbfc}tbody tr:hover{background:#eef4ff}td.cell{cursor:help}
td.cell:focus{outline:2px solid var(--accent)}.interval{display:block;font-size:.72rem;color:var(--muted)}
td.outside{color:var(--bad);font-weight:600}.table2 th{cursor:default}
.t2grid td,.t2grid th{padding:.15rem .35rem}.t2grid td.num{text-align:right}.t2grid td.who{white-space:normal;min-width:9rem;max-width:15rem;font-size:.78rem}
.t2grid tr.paper td{background:var(--head);font-weight:600}.t2grid tbody th{text-align:left;vertical-align:top;white-space:normal;max-width:8rem}
.notes{color:var(--muted);font-size:.8rem;max-width:80rem;overflow-wrap:anywhere}.shown{color:var(--muted);font-size:.8rem;margin:.2rem 0}
.figures{display:flex;flex-wrap:wrap;gap:.8rem}figure{margin:0;max-width:min(640px,100%)}figure img{max-width:100%;border:1px solid var(--line)}
th[hidden],td[hidden]{display:none}
figcaption{font-size:.78rem;color:var(--muted)}.placeholder{width:320px;height:200px;display:flex;align-items:center;justify-content:center;text-align:center;padding:1rem;border:2px dashed var(--bad);color:var(--bad);background:#fff5f5}
.problems{margin:.6rem 1.2rem;padding:.5rem .8rem;border:1px solid var(--bad);border-radius:6px;color:var(--bad);background:#fff5f5}
dialog{max-width:min(60rem,95vw);border:1px solid var(--line);border-radius:8px;padding:1rem 1.2rem}dialog .close{float:right;font-size:1.2rem;border:0;background:none;cursor:pointer}
dialog table td{white-space:normal}dialog code{font-size:.8rem}footer{color:var(--muted);padding:1rem 1.2rem;border-top:1px solid var(--line);font-size:.8rem}
code{font-family:ui-monospace,SFMono-Regular,Menlo,monospace;background:#eff1f3;padding:0 .2em;border-radius:3px}
section.lb-table.headline h2{font-size:1.15rem}
"""

_JS = r"""
(function(){
  "use strict";
  var filters = Array.prototype.slice.call(document.querySelectorAll("[data-filter]"));
  function state(){ var s = {}; filters.forEach(function(f){ if (f.value) s[f.dataset.filter] = f.value; }); return s; }
  function apply(){
    var s = state();
    document.querySelectorAll("section.lb-table").forEach(function(sec){
      var on = (!s.source || sec.dataset.source === s.source) && (!s.protocol || sec.dataset.protocol === s.protocol);
      var shown = 0, rows = sec.querySelectorAll("tbody tr");
      rows.forEach(function(tr){
        var ok = on && (!s.method || tr.dataset.method === s.method) &&
          (!s.preset || (" " + tr.dataset.presets + " ").indexOf(" " + s.preset + " ") >= 0);
        tr.hidden = !ok; if (ok) shown++;
      });
      sec.hidden = !on || shown === 0;
      var note = sec.querySelector(".shown");
      if (note) note.textContent = shown === rows.length ? "" : shown + " of " + rows.length + " rows shown (filtered)";
    });
    var parts = Object.keys(s).sort().map(function(k){ return k + "=" + encodeURIComponent(s[k]); });
    var hash = parts.length ? "#" + parts.join("&") : "";
    if (location.hash !== hash) history.replaceState(null, "", hash || location.pathname);
    document.querySelectorAll("header nav a").forEach(function(a){ a.href = a.getAttribute("href").split("#")[0] + (a.dataset.anchor || hash); });
  }
  function load(){
    var s = {};
    location.hash.replace(/^#/, "").split("&").forEach(function(p){ var kv = p.split("="); if (kv[0]) s[kv[0]] = decodeURIComponent(kv[1] || ""); });
    filters.forEach(function(f){
      var v = s[f.dataset.filter] || "";
      if (v && !Array.prototype.some.call(f.options, function(o){ return o.value === v; })) v = "";
      f.value = v;
    });
    apply();
  }
  filters.forEach(function(f){ f.addEventListener("change", apply); });
  var reset = document.getElementById("f-reset");
  if (reset) reset.addEventListener("click", function(){ filters.forEach(function(f){ f.value = ""; }); apply(); });
  window.addEventListener("hashchange", load);

  function sortValue(td, type){
    if (type === "num") { var v = td.dataset.value; return v === undefined ? null : parseFloat(v); }
    return td.textContent.trim();
  }
  document.querySelectorAll("table.sortable").forEach(function(table){
    var ths = table.querySelectorAll("thead th");
    ths.forEach(function(th, col){
      th.addEventListener("click", function(){
        var dir = th.getAttribute("aria-sort") === "descending" ? "ascending" : "descending";
        if (th.dataset.type === "text" && !th.hasAttribute("aria-sort")) dir = "ascending";
        ths.forEach(function(o){ o.removeAttribute("aria-sort"); });
        th.setAttribute("aria-sort", dir);
        var body = table.tBodies[0], rows = Array.prototype.slice.call(body.rows);
        rows.map(function(tr, i){ return {tr: tr, i: i, v: sortValue(tr.cells[col], th.dataset.type)}; })
          .sort(function(a, b){
            if (a.v === null && b.v === null) return a.i - b.i;
            if (a.v === null) return 1; if (b.v === null) return -1;
            var c = a.v < b.v ? -1 : a.v > b.v ? 1 : 0;
            return (dir === "ascending" ? c : -c) || a.i - b.i;
          }).forEach(function(o){ body.appendChild(o.tr); });
      });
    });
  });

  document.querySelectorAll("select.colgroup").forEach(function(sel){
    var table = sel.closest("section").querySelector("table.sortable");
    var groups = Array.prototype.map.call(table.querySelectorAll("thead th"), function(th){ return th.dataset.group || ""; });
    function pick(){
      var g = sel.value;
      Array.prototype.forEach.call(table.rows, function(tr){
        Array.prototype.forEach.call(tr.cells, function(c, j){ c.hidden = !!(g && groups[j] && groups[j] !== g); });
      });
    }
    sel.addEventListener("change", pick); pick();
  });

  var dialog = document.getElementById("detail"), dbody = document.getElementById("detail-body");
  function esc(t){ var d = document.createElement("div"); d.textContent = String(t); return d.innerHTML; }
  var registry = JSON.parse((document.getElementById("lb-records") || {}).textContent || "[]");
  function show(td){
    var title = td.title.split(";")[0], section = td.closest("section");
    var h = "<h3>" + esc(title) + "</h3><p>" + esc(section.querySelector("h2").textContent) + "</p>";
    h += "<table><thead><tr><th>seed</th><th>value</th><th>record, provenance</th></tr></thead><tbody>";
    td.dataset.src.split(" ").forEach(function(ref){
      var k = ref.indexOf(":"), s = Object.assign({}, registry[parseInt(ref.slice(0, k), 10)]);
      s.value = ref.slice(k + 1);
      h += "<tr><td>" + esc(s.seed) + "</td><td>" + esc(s.value) + "</td><td><code>" + esc(s.record) + "</code><br>task " + esc(s.task) +
        " · matcher preset " + esc(s.preset) + "<br>made " + esc(s.created) + " · git " + esc(s.git) + "<br>" + esc(s.cpu) + " · " + esc(s.how_run) +
        "<br>draw it: <code class=\"explain\">" + esc(s.explain) + "</code></td></tr>";
    });
    dbody.innerHTML = h + "</tbody></table>";
    if (dialog.showModal) dialog.showModal(); else dialog.setAttribute("open", "");
  }
  document.querySelectorAll("td.cell[data-src]").forEach(function(td){
    td.addEventListener("click", function(){ show(td); });
    td.addEventListener("keydown", function(e){ if (e.key === "Enter") show(td); });
  });
  document.querySelectorAll("img[data-missing]").forEach(function(img){
    function fail(){
      var fig = img.closest("figure"); var div = document.createElement("div");
      div.className = "placeholder"; div.textContent = img.dataset.missing;
      fig.classList.add("missing"); img.parentNode.replaceWith(div);
    }
    if (img.complete && img.naturalWidth === 0 && img.getAttribute("src")) fail(); else img.addEventListener("error", fail);
  });
  load();
})();
"""
