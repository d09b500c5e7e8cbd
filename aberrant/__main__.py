"""``python -m aberrant``: the command line."""

from aberrant.cli import main

raise SystemExit(main())
