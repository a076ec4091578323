"""A pytest plugin for the opt-in mutation run only (tools/mutation.sh loads it with
``-p tests.mutmut_order``; the default test run never does): run each mutant's tests quickest
first, by the durations mutmut measured on the unmutated code. mutmut stops at a mutant's first
failing test (``-x``), so a mutant that a quick test kills costs that test, not the slow ones."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any


def pytest_collection_modifyitems(config: Any, items: list[Any]) -> None:
    if not os.environ.get("MUTANT_UNDER_TEST", "").startswith("safl_bench."):
        return
    try:
        stats = json.loads(Path("mutmut-stats.json").read_text())
        duration = stats["duration_by_test"]
    except (OSError, ValueError, KeyError):
        return
    items.sort(key=lambda item: duration.get(item.nodeid, 0.0))
