"""``python -m benchmarks``: every stage against its raw baseline (see momentid.bench)."""

import sys

from momentid.bench import main

sys.exit(main())
