"""Hand-made mutants of the numba kernels (opt-in, like tools/mutation.sh).

mutmut never mutates a decorated function, so the ``@numba.njit`` kernels of
`safl_bench.matching.matcher` (``_enhance_kernel``, ``_cand_range``, ``_search_kernel``) and of
`safl_bench.evaluation.uncertainty` (``_count_blocks``, ``_row``, ``_weighted_kernel``,
``_block_kernel``) get no mutant from it (its trampolines could not run inside nopython code
anyway). This script applies each mutation below to a copy of the package in a temporary folder
and runs the tests of that module against that copy, with a numba cache folder of the mutant's
own: a kernel compiled from other source (the unmutated code, or another mutant) can never be
loaded in its place. A mutant that the tests do not kill is listed with its line; the exit
status is the number of survivors.

    python tools/kernel_mutants.py            # all mutants, one after the other
    python tools/kernel_mutants.py 0 3        # only these (0-12: matcher, 13-: uncertainty)
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

#: module -> (its file, where its kernels start and end, the tests that run against a mutant)
TARGETS = {
    "matcher": (
        "safl_bench/matching/matcher.py",
        "# --------------------------------------------------------------------------- kernels",
        "# --------------------------------------------------------------------------- public API",
        ["tests/test_matching.py", "tests/test_matching_values.py"],
    ),
    "uncertainty": (
        "safl_bench/evaluation/uncertainty.py",
        "@numba.njit(cache=True)\ndef _count_blocks",
        "def _run_ends(",
        ["tests/test_uncertainty_cases.py", "tests/test_uncertainty.py"],
    ),
}

#: (the exact source text, its replacement): one operator or bound each, in the kernels only
MATCHER_MUTANTS = [
    # _enhance_kernel
    ("ok = var > floor", "ok = var >= floor"),
    ("var = (c2[j + after + 1] - c2[j - before] - s1 * mu) * inv_nm1",
     "var = (c2[j + after + 1] - c2[j - before] - s1 * mu) * inv_n"),
    ("            if w < 2:\n", "            if w < 3:\n"),
    ("b = min(ndb, j + after + 1)", "b = min(ndb, j + after)"),
    ("floor = 1e-12 * max(", "floor = 1e-3 * max("),
    # _cand_range
    ("        lo = max(lo, -o)\n        hi = min(hi, ndb - o)\n    return lo, min(hi, jend)",
     "        lo = max(lo, -o)\n        hi = min(hi, ndb - o + 1)\n    return lo, min(hi, jend)"),
    # _search_kernel
    ("k1 = min(L, nq - T - u_lo)", "k1 = min(L, nq - T - u_lo - 1)"),
    ("if (skip_edges and cnt < L) or jend <= 0:", "if (skip_edges and cnt <= L) or jend <= 0:"),
    ("            if best[j] < bval:\n", "            if best[j] <= bval:\n"),
    ("best_s[T] = bval / cnt", "best_s[T] = bval / L"),
    ("if abs(j - jstar) > half and best[j] < sv:", "if abs(j - jstar) >= half and best[j] < sv:"),
    ("acc[j] += Dh[r, ndb - 1]", "acc[j] += Dh[r, ndb - 2]"),
    ("vel[T] = np.argmin(np.abs(tot - bval))", "vel[T] = np.argmax(np.abs(tot - bval))"),
]

UNCERTAINTY_MUTANTS = [
    # _count_blocks (block_weights)
    ("out[r, (starts[r, b] + k) % n] += 1", "out[r, (starts[r, b] + k + 1) % n] += 1"),
    ("        for b in range(starts.shape[1]):\n            for k in range(block):",
     "        for b in range(starts.shape[1]):\n            for k in range(block - 1):"),
    # _row: the PR thresholds
    ("        elif wrong[i]:\n            fp += w[i]", "        else:\n            fp += w[i]"),
    ("        if not desc_end[g]:\n            continue", "        if False:\n            continue"),
    ("if fp == 0 and tp > r100:", "if fp <= 1 and tp > r100:"),
    ("if tp / decided >= AUTHORS_PRECISION and tp > a99:",
     "if tp / decided > AUTHORS_PRECISION and tp > a99:"),
    ("f1 = max(f1, 2 * tp / (decided + pos))", "f1 = max(f1, 2 * tp / (decided + n_correct))"),
    ("p_r0 = tp / decided", "p_r0 = tp / pos"),
    # _row: the ROC AUC (the first is issue #37's: ties counted in full, 8/9 for the metric's 7/9)
    ("auc_num += pos_g * (below + 0.5 * within)", "auc_num += pos_g * (below + within)"),
    ("            elif correct[i]:\n                pos_g += w[i]",
     "            else:\n                pos_g += w[i]"),
    ("        below += within\n", "        below = within\n"),
    # _row: the measures
    ("out[6] = (p_r0 + r_of_correct) / 2 if pos > 0 else nan",
     "out[6] = (p_r0 + r_at_100) / 2 if pos > 0 else nan"),
    ("out[8] = (a99 / n_correct if n_correct > 0 else 0.0)",
     "out[8] = (a99 / pos if n_correct > 0 else 0.0)"),
    ("out[9] = n5 / pos if pos > 0 else nan", "out[9] = n10 / pos if pos > 0 else nan"),
    # _block_kernel (block_measures)
    ("                if j == n:\n                    j = 0", "                if j == n - 1:\n                    j = 0"),
    ("                w[j] += 1.0\n", "                w[j] = 1.0\n"),
]

#: (module, old, new); the matcher's first, numbered as before
MUTANTS = [("matcher", *m) for m in MATCHER_MUTANTS] + [("uncertainty", *m) for m in UNCERTAINTY_MUTANTS]


def run(i: int, target: str, old: str, new: str) -> bool:
    """True when the tests kill mutant i (of module `target`)."""
    path, first, last, tests = TARGETS[target]
    source = (ROOT / path).read_text()
    start = source.index(first)
    end = source.index(last)
    kernels = source[start:end]
    if kernels.count(old) != 1:
        raise SystemExit(f"mutant {i}: {old!r} is not exactly once in the kernels")
    with tempfile.TemporaryDirectory(prefix=f"kernel-mutant-{i}-") as tmp:
        work = Path(tmp)
        shutil.copytree(ROOT / "safl_bench", work / "safl_bench",
                        ignore=shutil.ignore_patterns("__pycache__"))
        shutil.copytree(ROOT / "tests", work / "tests", ignore=shutil.ignore_patterns("__pycache__"))
        shutil.copy(ROOT / "pyproject.toml", work / "pyproject.toml")
        mutated = source[:start] + kernels.replace(old, new) + source[end:]
        (work / path).write_text(mutated)
        env = dict(os.environ, NUMBA_CACHE_DIR=str(work / "numba-cache"), PYTHONPATH=str(work),
                   NUMBA_NUM_THREADS=os.environ.get("NUMBA_NUM_THREADS", "1"))
        probe = subprocess.run(
            [sys.executable, "-c", f"import {path[:-3].replace('/', '.')} as m; print(m.__file__)"],
            cwd=work, env=env, capture_output=True, text=True, check=True)
        if not probe.stdout.strip().startswith(str(work)):  # the copy, never the checkout
            raise SystemExit(f"mutant {i}: imported {probe.stdout.strip()}, not the mutated copy")
        proc = subprocess.run(
            [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *tests],
            cwd=work, env=env, capture_output=True, text=True)
        return proc.returncode != 0


def main(argv: list[str]) -> int:
    chosen = [int(a) for a in argv] or list(range(len(MUTANTS)))
    survivors = []
    t0 = time.perf_counter()
    for i in chosen:
        target, old, new = MUTANTS[i]
        killed = run(i, target, old, new)
        print(f"{i:2d} {target} {'killed  ' if killed else 'SURVIVED'} {old.strip()!r} -> "
              f"{new.strip()!r}", flush=True)
        if not killed:
            survivors.append(i)
    print(f"{len(chosen) - len(survivors)} of {len(chosen)} killed in "
          f"{time.perf_counter() - t0:.0f} s; survivors: {survivors}")
    return len(survivors)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
