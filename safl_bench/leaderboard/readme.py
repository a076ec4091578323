"""The README's generated blocks: text between a start and an end marker that `safl-bench
leaderboard` rewrites from the records (the headline, `headline.readme_block`; Table II beside
ours, `table2.readme_block`), so a regeneration keeps the README's numbers true."""

from __future__ import annotations

import os
from pathlib import Path

from safl_bench.common.atomic import atomic_write_text
from safl_bench.errors import DataError


def replace_block(readme: str | os.PathLike[str], start: str, end: str, block: str, what: str) -> bool:
    """Put `block` (markers included) in place of the text from `start` to `end` in `readme`;
    True when the file changed. A README without the markers is left alone; one with a start
    marker and no end marker (or the end before the start) is refused in one line naming the
    file and `what` the block is."""
    path = Path(readme)
    text = path.read_text(encoding="utf-8")
    i, j = text.find(start), text.find(end)
    if i < 0 and j < 0:
        return False
    if i < 0 or j < i:
        raise DataError(f"{path}: the {what} markers {start} … {end} are not in order")
    new = text[:i] + block + text[j + len(end):]
    if new == text:
        return False
    atomic_write_text(path, new)
    return True
