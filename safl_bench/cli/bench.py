"""`safl-bench bench`: not available yet (lands with the run command, issue #6)."""

from __future__ import annotations

import argparse

from safl_bench.errors import SaflError

HELP = "(not available yet: issue #6)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """No arguments until the command lands."""


def main(args: argparse.Namespace) -> int:
    raise SaflError("this command is not available yet (issue #6)")
