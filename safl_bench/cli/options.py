"""Option parsing shared by subcommands."""

from __future__ import annotations

import json
from typing import Any

from safl_bench.errors import ConfigError


def parse_key_values(items: list[str], flag: str) -> dict[str, Any]:
    """KEY=VALUE pairs -> dict; VALUE is JSON when it parses (numbers, true/false, lists), else
    a string. `flag` names the option in the error message."""
    out: dict[str, Any] = {}
    for item in items:
        key, sep, raw = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"{flag} takes KEY=VALUE, got {item!r}")
        try:
            out[key] = json.loads(raw)
        except json.JSONDecodeError:
            out[key] = raw
    return out
