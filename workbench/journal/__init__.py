"""A session's journal: the store (an append-only event log and its frames on disk), the rebuild of a
session from it, which events a discard leaves out, the ``nbv replay`` check, and the trash of deleted
sessions. docs/journal.md is the format's reference."""

from workbench.journal.check import JournalCheck, check_journal

__all__ = ["JournalCheck", "check_journal"]
