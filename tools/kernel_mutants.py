"""Hand-made mutants of the matcher's numba kernels (opt-in, like tools/mutation.sh).

mutmut never mutates a decorated function, so the ``@numba.njit`` kernels of
`safl_bench.matching.matcher` (``_enhance_kernel``, ``_cand_range``, ``_search_kernel``) get no mutant
from it (its trampolines could not run inside nopython code anyway). This script applies each
mutation below to a copy of the package in a temporary folder and runs the matching tests
against that copy, with a numba cache folder of the mutant's own: a kernel compiled from other
source (the unmutated code, or another mutant) can never be loaded in its place. A mutant that
the tests do not kill is listed with its line; the exit status is the number of survivors.

    python tools/kernel_mutants.py            # all mutants, one after the other
    python tools/kernel_mutants.py 0 3        # only these
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
TESTS = ["tests/test_matching.py", "tests/test_matching_values.py"]

#: (the exact source text, its replacement): one operator or bound each, in the kernels only
MUTANTS = [
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


def run(i: int, old: str, new: str) -> bool:
    """True when the tests kill mutant i."""
    source = (ROOT / "safl_bench" / "matching" / "matcher.py").read_text()
    start = source.index("# --------------------------------------------------------------------------- kernels")
    end = source.index("# --------------------------------------------------------------------------- public API")
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
        (work / "safl_bench" / "matching" / "matcher.py").write_text(mutated)
        env = dict(os.environ, NUMBA_CACHE_DIR=str(work / "numba-cache"), PYTHONPATH=str(work),
                   NUMBA_NUM_THREADS=os.environ.get("NUMBA_NUM_THREADS", "1"))
        probe = subprocess.run(
            [sys.executable, "-c", "import safl_bench.matching.matcher as m; print(m.__file__)"],
            cwd=work, env=env, capture_output=True, text=True, check=True)
        if not probe.stdout.strip().startswith(str(work)):  # the copy, never the checkout
            raise SystemExit(f"mutant {i}: imported {probe.stdout.strip()}, not the mutated copy")
        proc = subprocess.run(
            [sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider", *TESTS],
            cwd=work, env=env, capture_output=True, text=True)
        return proc.returncode != 0


def main(argv: list[str]) -> int:
    chosen = [int(a) for a in argv] or list(range(len(MUTANTS)))
    survivors = []
    t0 = time.perf_counter()
    for i in chosen:
        old, new = MUTANTS[i]
        killed = run(i, old, new)
        print(f"{i:2d} {'killed  ' if killed else 'SURVIVED'} {old.strip()!r} -> {new.strip()!r}",
              flush=True)
        if not killed:
            survivors.append(i)
    print(f"{len(chosen) - len(survivors)} of {len(chosen)} killed in "
          f"{time.perf_counter() - t0:.0f} s; survivors: {survivors}")
    return len(survivors)


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
