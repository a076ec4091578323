"""The command-line reference, printed from the parser itself (the docs' "Command line" page).

`commands()` walks `build_parser()`'s sub-parsers, so a command or option added to the CLI shows
up in the docs without anyone writing it down. The page in the repository holds the output
between `START` and `END`, so that it reads on the repository's page too; a test fails when it
is stale, and ``python -m safl_bench.cli.reference`` rewrites it.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterator
from pathlib import Path

from safl_bench.cli import build_parser

START = "<!-- cli-reference:start (generated: python -m safl_bench.cli.reference) -->"
END = "<!-- cli-reference:end -->"
#: The committed page that holds the reference.
PAGE = Path(__file__).resolve().parents[2] / "docs" / "reference" / "cli.md"


def commands(parser: argparse.ArgumentParser | None = None,
             prefix: tuple[str, ...] = ()) -> Iterator[tuple[tuple[str, ...], argparse.ArgumentParser]]:
    """(command words, parser) of `safl-bench` and every command under it, depth first."""
    parser = parser or build_parser()
    yield prefix, parser
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                yield from commands(sub, (*prefix, name))


def cli_reference_markdown() -> str:
    """Markdown: one section per command with its `--help` output as printed."""
    previous = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = "100"  # argparse wraps to the terminal; fix it for the docs
    try:
        parts = []
        for words, parser in commands():
            name = " ".join(("safl-bench", *words))
            parser.prog = name
            level = "#" * min(2 + len(words) - (1 if words else 0), 4)
            parts += [f"{level} `{name}`", "", "```text", parser.format_help().rstrip(), "```", ""]
        return "\n".join(parts)
    finally:
        if previous is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = previous


def with_reference(page: str) -> str:
    """`page` with the text between `START` and `END` replaced by `cli_reference_markdown`."""
    head, start, rest = page.partition(START)
    _, end, tail = rest.partition(END)
    if not start or not end:
        raise ValueError(f"the page has no {START} ... {END} block")
    return f"{head}{START}\n\n{cli_reference_markdown()}\n{END}{tail}"


def main() -> int:
    """Rewrite the committed page's reference block."""
    text = PAGE.read_text(encoding="utf-8")
    new = with_reference(text)
    if new != text:
        PAGE.write_text(new, encoding="utf-8")
        print(f"rewrote {PAGE}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
