"""Class mode: a teacher's class of seats (each an ordinary session), joined by students with a short code."""

from workbench.classes.classes import Classes
from workbench.classes.classroom import ClassRoom, Seat
from workbench.classes.picture import cloud_picture

__all__ = ["ClassRoom", "Classes", "Seat", "cloud_picture"]
