"""MkDocs hooks: pages generated from the code at build time, so the docs cannot drift.

The `<!-- cli-reference:start ... -->` block of a page becomes the help of every `safl-bench`
command, printed by the parser itself (`safl_bench.cli.reference`), as the committed page holds
it when it is current.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

CLI_MARKER = "<!-- cli-reference:start"
ROOT = Path(__file__).resolve().parents[1]


def on_config(config: Any) -> Any:
    """Import safl_bench from this checkout, whatever an installed copy points at."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    return config


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    if CLI_MARKER in markdown:
        from safl_bench.cli.reference import with_reference

        markdown = with_reference(markdown)
    return markdown
