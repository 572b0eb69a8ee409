"""``python -m benchmarks``: every stage against its raw baseline (see benchmarks.bench)."""

import sys

from benchmarks.bench import main

sys.exit(main())
