"""``python -m benchmarks``: an alias of ``jaxgest bench`` (the suite is :mod:`jaxgest.bench`)."""

import sys

from jaxgest.bench.suite import main

sys.exit(main())
