"""``python -m drivers.wrench.sim``: the simulated controller as a process (see cli.py)."""

from drivers.wrench.sim.cli import main

raise SystemExit(main())
