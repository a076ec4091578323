"""The command-line reference, printed from the parser itself (the docs' "Command line" page).

`commands()` walks `build_parser()`'s sub-parsers, so a command or option added to the CLI shows
up in the docs without anyone writing it down.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterator

from safl_bench.cli import build_parser


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
