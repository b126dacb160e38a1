"""``python -m experiments ...``: see :mod:`experiments.driver`."""

from experiments.driver import main

raise SystemExit(main())
