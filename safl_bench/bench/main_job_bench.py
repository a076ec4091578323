"""Benchmark of the README's main job: `safl-bench run --method stable_afl` from an empty cache,
then again with everything cached (issue #37: at most 600 s from nothing on the 2-core machine,
seconds when cached).

    safl-bench bench main-job [--method stable_afl]

Runs the command as a user does, in a child process, with a scratch `$SAFL_HOME` (so the
synthetic default is generated, its views rendered and the descriptors computed from nothing)
and a scratch results folder; the second run reuses the records. Prints the wall time of each,
the machine's load average before the first (a busy machine inflates the figure: quote it with
its load) and the child's exit status. Nothing of the user's cache or results is touched.
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any


def run(method: str = "stable_afl", extra: list[str] | None = None) -> dict[str, Any]:
    """Time the main job twice (empty cache, then cached); returns the figures."""
    command = [sys.executable, "-m", "safl_bench", "run", "--method", method, *(extra or [])]
    figures: dict[str, Any] = {"command": " ".join(["safl-bench", *command[3:]]),
                               "load_average_before": list(os.getloadavg()),
                               "cpu_count": os.cpu_count()}
    with tempfile.TemporaryDirectory() as scratch:
        env = {**os.environ, "SAFL_HOME": str(Path(scratch) / "home")}
        results = str(Path(scratch) / "results")
        for label in ("empty_cache_s", "cached_s"):
            start = time.perf_counter()
            done = subprocess.run([*command, "--results", results], env=env, capture_output=True,
                                  text=True, check=False)
            figures[label] = time.perf_counter() - start
            figures[f"{label}_returncode"] = done.returncode
            if label == "empty_cache_s":
                figures["output"] = done.stdout
            if done.returncode != 0:
                figures["error"] = (done.stderr or done.stdout).strip().splitlines()[-1:]
                break
    return figures


def format_results(figures: dict[str, Any]) -> str:
    """The figures as the lines the command prints."""
    load = ", ".join(f"{v:.1f}" for v in figures["load_average_before"])
    lines = [f"main job: {figures['command']} ({figures['cpu_count']} CPUs, load average before: {load})"]
    for label, what in (("empty_cache_s", "from an empty cache"), ("cached_s", "cached")):
        if label in figures:
            status = figures[f"{label}_returncode"]
            lines.append(f"  {what}: {figures[label]:.1f} s" + (f" (exit {status})" if status else ""))
    if "error" in figures:
        lines.append(f"  error: {' '.join(figures['error'])}")
    return "\n".join(lines)
