"""`python -m safl_bench` is the `safl-bench` command."""

import sys

from safl_bench.cli import main

sys.exit(main())
