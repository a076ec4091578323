#!/usr/bin/env bash
# Opt-in mutation testing of the scoring code: metrics, evaluation cell, groundtruth, matcher
# (issue #24), the bootstrap intervals and the leaderboard's ranking rule (issue #37). Never
# part of `python -m pytest`. Run it in a checkout nobody else is editing (it writes mutants/;
# e.g. `git worktree add /tmp/mut HEAD`). Needs the `mutation` extra:
#     pip install -e '.[test,mutation]'
#     tools/mutation.sh            # a fresh run: mutants/ is rebuilt from the working tree
#     tools/mutation.sh --resume   # keep mutants/ and its results (after an interrupted run)
# Then `mutmut results` lists the survivors and `mutmut show NAME` shows one.
# Configuration: [tool.mutmut] in pyproject.toml; results and survivors: tests/MUTATION.md.
set -euo pipefail
cd "$(dirname "$0")/.."
if [[ "${1:-}" != "--resume" ]]; then
    rm -rf mutants
fi
# One numba thread per mutant worker (the workers run side by side), and a numba cache of
# this run's own: no compiled kernel from another checkout or an earlier run is ever loaded.
export NUMBA_NUM_THREADS="${NUMBA_NUM_THREADS:-1}"
export NUMBA_CACHE_DIR="$PWD/mutants/.numba-cache"
mkdir -p "$NUMBA_CACHE_DIR"
# wall and CPU seconds of the whole run (CPU / cores: what it takes on an idle machine)
/usr/bin/time -f "mutation run: %e s wall, %U s user + %S s system CPU" \
    mutmut run --max-children "${MUTMUT_CHILDREN:-$(nproc)}"
mutmut results
