"""The process-parameter database (SQLAlchemy): vehicle models, bolts, parameters, records.

The models, the repository used by the daemon and the migrations arrive with the daemon issue.
"""
