"""A session's journal: the store (an append-only event log and its frames on disk), the rebuild of a
session from it, which events a discard leaves out, the ``nbv replay`` check, the trash of deleted
sessions, and a session's timeline (the session after each view). docs/journal.md is the format's reference."""

from workbench.journal.check import JournalCheck, check_journal
from workbench.journal.timeline import journal_timeline

__all__ = ["JournalCheck", "check_journal", "journal_timeline"]
