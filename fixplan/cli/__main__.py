"""``python -m fixplan.cli ARGS``: the same as ``fixplan ARGS``."""

from fixplan.cli import main

raise SystemExit(main())
