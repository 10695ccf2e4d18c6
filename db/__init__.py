"""The process-parameter database: vehicle models, bolts, versioned parameters, vehicles and
tightening records.

- ``errors``: the layer's own errors (``db`` imports nothing from ``stationd``; the bolt
  table's YAML is read by ``stationd.boltfile``);
- ``location``, ``reach``: whether an SQLite file can keep what is written, and why a path
  cannot be reached in words (the station's readers of its files say it so too);
- ``spacing``: the one bolt-spacing rule (the table's check and the matcher's);
- ``bolts``: the bolt table as typed values and its YAML form (the export);
- ``models``: the SQLAlchemy schema; ``migrations``: the alembic revisions that create it;
- ``engine``, ``migrate``: any SQLAlchemy URL, SQLite in WAL mode with foreign keys on,
  migrated in code when opened;
- ``repository``: the API the daemon and ``stationd db`` use (``importer`` and ``report``
  hold its import diff and vehicle reports).
"""
