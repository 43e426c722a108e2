"""A session's journal: the store (an append-only event log and its frames on disk), the rebuild of a
session from it, which events a discard leaves out, the ``nbv replay`` check, the trash of deleted
sessions, a session's timeline (the session after each view) and a session as a ROS 2 bag (docs/bags.md).
docs/journal.md is the format's reference."""

from workbench.journal.bag import BagExport, bag_bytes, export_bag
from workbench.journal.check import JournalCheck, check_journal
from workbench.journal.timeline import journal_timeline

__all__ = ["BagExport", "JournalCheck", "bag_bytes", "check_journal", "export_bag", "journal_timeline"]
