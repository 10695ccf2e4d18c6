"""Alembic revisions, one file each, oldest first (``down_revision`` links them)."""
