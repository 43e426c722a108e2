"""A session's journal: the store (an append-only event log and its frames on disk), the rebuild of a
session from it, and the replay check of ``nbv replay``. docs/journal.md is the format's reference."""
