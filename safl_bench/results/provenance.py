"""Where a result came from: library versions, hardware and git revision.

Every result record carries an `Environment`, so a number on the leaderboard can be traced to
the code and machine that produced it. Nothing here imports heavy libraries: versions come from
the installed distributions' metadata, and torch's thread count is read only when the caller has
already imported torch (a run whose methods use torch has).
"""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from dataclasses import dataclass, field
from importlib import metadata
from pathlib import Path
from typing import ClassVar

from pydantic import ConfigDict

from safl_bench.results.fields import RECORD_CONFIG, Count, Text

#: Distributions whose versions are recorded with every result (distribution names).
LIBRARIES: tuple[str, ...] = (
    "safl-bench",
    "numpy",
    "scipy",
    "torch",
    "scikit-learn",
    "gymnasium",
    "numba",
    "pandas",
    "matplotlib",
)


@dataclass(frozen=True)
class Environment:
    """The software and hardware a result was produced on."""

    __pydantic_config__: ClassVar[ConfigDict] = RECORD_CONFIG

    python: Text
    libraries: dict[Text, Text] = field(default_factory=dict)
    platform: Text = ""
    cpu_model: Text = ""
    #: the CPU's vector instruction sets that set a network's speed (`cpu_vector`): one model
    #: name covers hosts with and without AVX-512 ("" in records made before it was recorded)
    cpu_vector: Text = ""
    cpu_cores: Count = 0
    torch_threads: Count | None = None
    git_revision: Text = ""


def library_versions(names: tuple[str, ...] = LIBRARIES) -> dict[str, str]:
    """Installed version of each distribution in `names` ("not installed" where absent)."""
    versions: dict[str, str] = {}
    for name in names:
        try:
            versions[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            versions[name] = "not installed"
    return versions


def cpu_model() -> str:
    """The CPU's model name (from /proc/cpuinfo on Linux, else `platform`)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                if key.strip() in ("model name", "Model", "Hardware") and value.strip():
                    return value.strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


#: the /proc/cpuinfo flags `cpu_vector` reports, narrowest first
VECTOR_FLAGS: tuple[str, ...] = ("avx2", "fma", "avx512f", "avx512_vnni", "avx512_bf16",
                                 "amx_tile", "amx_bf16")


def cpu_vector() -> str:
    """The vector instruction sets of `VECTOR_FLAGS` this CPU has, space-separated ("" where
    /proc/cpuinfo is not there). Timings are comparable only between hosts that agree on them:
    the same "AMD EPYC" ran BEVPlace at 97 ms a frame with AVX-512 and at 342 ms with AVX2 only."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as fh:
            for line in fh:
                key, _, value = line.partition(":")
                if key.strip() == "flags":
                    have = set(value.split())
                    return " ".join(f for f in VECTOR_FLAGS if f in have)
    except OSError:
        pass
    return ""


def cpu_cores() -> int:
    """Cores this process may run on (its affinity where the OS tells, else the CPU count)."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


def torch_threads() -> int | None:
    """torch's intra-op thread count if torch is already imported, else None."""
    torch = sys.modules.get("torch")
    if torch is None:
        return None
    return int(torch.get_num_threads())


def _git(args: list[str], cwd: Path) -> str | None:
    try:
        done = subprocess.run(
            ["git", *args], cwd=cwd, capture_output=True, text=True, timeout=10, check=False
        )
    except (OSError, subprocess.TimeoutExpired):
        return None
    return done.stdout.strip() if done.returncode == 0 else None


def git_revision(where: Path | None = None) -> str:
    """The git commit of the safl-bench source tree, with " (dirty)" for uncommitted changes.

    Outside a git checkout (an installed wheel) it is "safl-bench <version>".
    """
    cwd = where if where is not None else Path(__file__).resolve().parent
    revision = _git(["rev-parse", "HEAD"], cwd)
    if not revision:
        return f"safl-bench {library_versions(('safl-bench',))['safl-bench']}"
    status = _git(["status", "--porcelain", "--untracked-files=no"], cwd)
    return f"{revision} (dirty)" if status else revision


def collect_environment() -> Environment:
    """The current process's environment, for a result record."""
    return Environment(
        python=platform.python_version(),
        libraries=library_versions(),
        platform=platform.platform(),
        cpu_model=cpu_model(),
        cpu_vector=cpu_vector(),
        cpu_cores=cpu_cores(),
        torch_threads=torch_threads(),
        git_revision=git_revision(),
    )
