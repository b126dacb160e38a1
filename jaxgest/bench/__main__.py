"""``python -m jaxgest.bench``: the same as ``jaxgest bench``."""

import sys

from jaxgest.bench.suite import main

sys.exit(main())
