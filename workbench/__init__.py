"""Supervised scanning, independent of HTTP and of the 3D scene.

A session (:class:`workbench.session.Session`) owns a planner, a cell and a lock; every state change
of a scan goes through it. Importing this package loads no fastapi, uvicorn or viser.
"""
