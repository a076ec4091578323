"""What the headline table is, said the same way in index.md, on the web page and in README.md.

The headline (chosen by `report.headline_rank`) is read with four facts beside it, source,
protocol, matcher preset and seeds, and one sentence on how to read recall at 100 % precision.
`update_readme` rewrites the block between `README_START` and `README_END` in a README from the
same table (`readme.replace_block`), so a regeneration keeps the README's numbers true.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence

from safl_bench.leaderboard.grouping import format_seeds
from safl_bench.leaderboard.readme import replace_block
from safl_bench.leaderboard.tables import Table
from safl_bench.results.records import ResultRecord

#: The one sentence a reader needs to read a headline cell.
READING = (
    "Recall at 100 % precision counts the true places found before the first wrong match, "
    "taking matches from the most confident down: one wrong match that is more confident than "
    "every right one makes a cell 0.0 even when most matches are right, so read F1max and "
    "Recall@1 (how many queries are matched correctly) and AUC (how well the confidence orders "
    "right before wrong) beside it; `safl-bench explain --method M --task ID` draws the wrong "
    "matches that set a zero."
)

#: Where the README's headline block sends a reader for every table.
README_LINK = ("`leaderboard/site/index.html` (open it from disk) and "
               "[leaderboard/index.md](leaderboard/index.md)")

README_START = "<!-- headline:start -->"
README_END = "<!-- headline:end -->"


def facts(table: Table, records: Sequence[ResultRecord]) -> list[tuple[str, str]]:
    """(name, value) of the source, protocol, matcher preset, seeds (and sequences) of `table`."""
    from safl_bench.matching.presets import label

    key = table.key
    sequences = sorted({r.task.sequence for r in records})
    presets = sorted({label(r.matcher) for r in records})
    protocol = f"{key.protocol}, task version v{key.task_version}"
    return [
        ("Source", key.source_label),
        ("Sequences" if len(sequences) > 1 else "Sequence", ", ".join(sequences) or "—"),
        ("Protocol", protocol),
        ("Matcher preset", ", ".join(presets) or "—"),
        ("Seeds", format_seeds(table.seeds)),
    ]


def facts_markdown(table: Table, records: Sequence[ResultRecord]) -> str:
    """The facts as one Markdown line."""
    return " · ".join(f"{name}: {value}" for name, value in facts(table, records))  # no bold: it means best


def readme_block(table: Table, records: Sequence[ResultRecord], link: str) -> str:
    """The README's headline block: facts, the table without its notes, the reading sentence."""
    bare = dataclasses.replace(table, notes=[])
    lines = [
        README_START,
        "<!-- written by `safl-bench leaderboard` from the leaderboard's records; do not edit -->",
        "",
        facts_markdown(table, records),
        "",
        bare.markdown(level=4).rstrip("\n"),
        "",
        READING,
        f"Every table, with filters and each cell's record: {link}.",
        README_END,
    ]
    return "\n".join(lines)


def update_readme(readme: str | os.PathLike[str], table: Table, records: Sequence[ResultRecord],
                  link: str = README_LINK) -> bool:
    """Rewrite the headline block of `readme` if it has the markers; True when the file changed.

    A README without the markers is left alone; one with a start marker and no end marker (or
    the end before the start) is refused in one line naming the file.
    """
    return replace_block(readme, README_START, README_END, readme_block(table, records, link), "headline")
