"""Allow ``python -m stationd``."""

from stationd.cli import main

raise SystemExit(main())
