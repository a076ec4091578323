"""`safl-bench data show`: not available yet (issue #2)."""

from __future__ import annotations

import argparse

from safl_bench.errors import SaflError

HELP = "(not available yet: issue #2)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """No arguments until the command lands."""


def main(args: argparse.Namespace) -> int:
    raise SaflError("this command is not available yet (issue #2)")
