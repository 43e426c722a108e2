"""A session's recording: a zip that plays the scan offline (app/scene/recording.py), from its timeline; and the
scan as a ROS 2 bag (workbench/journal/bag.py) for ``ros2 bag play``, RViz and Foxglove."""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query, Response

from app.api.deps import SessionDep
from app.scene.recording import STEP_SECONDS, build_recording
from workbench import Conflict

router = APIRouter(prefix="/sessions/{session_id}/recording", tags=["recording"])


@router.get("", response_class=Response, responses={200: {"content": {"application/zip": {}}}})
def recording(session: SessionDep, step_seconds: Annotated[float, Query(gt=0.0, le=60.0)] = STEP_SECONDS) -> Response:
    """The scan as a zip, its files in one folder ``nbv-ID-recording/`` (``index.html``: viser's client with the scene embedded, one step per view, plus
    ``scene.viser`` and ``steps.json``) that plays from its unzipped folder or any static host, offline. 409
    without a journal or a view. ``step_seconds``: playback time per view."""
    steps = session.history.steps()
    if not steps:
        raise Conflict(f"session {session.id}: no view yet to record")
    folder = f"nbv-{session.id}-recording"
    title = f"NBV scan {session.id} · {session.status()['model']}"
    built = build_recording(steps, session.scene_data(), title, step_seconds, folder=folder)
    return Response(
        built.data,
        media_type="application/zip",
        headers={
            "Content-Disposition": f'attachment; filename="{folder}.zip"',
            "Cache-Control": "no-store",
        },
    )


bag_router = APIRouter(prefix="/sessions/{session_id}", tags=["recording"])
BAG_MEDIA = {"mcap": "application/x-mcap", "db3": "application/vnd.sqlite3"}


def _bag(session: SessionDep, fmt: Literal["mcap", "db3"], distro: str) -> Response:
    try:
        import rosbags  # noqa: F401
    except ImportError:
        raise Conflict("this server cannot write ROS 2 bags: install its ros2 extra (rosbags)") from None
    from workbench.journal import bag_bytes

    journal = session.journal
    if journal is None:
        raise Conflict(f"session {session.id}: no journal to export (the server runs without one)")
    if session.status()["iteration"] == 0:
        raise Conflict(f"session {session.id}: no view yet to export")
    data, _ = bag_bytes(journal.directory, f".{fmt}", distro, session.planner.cloud)
    return Response(
        data,
        media_type=BAG_MEDIA[fmt],
        headers={
            "Content-Disposition": f'attachment; filename="nbv-{session.id}.{fmt}"',
            "Cache-Control": "no-store",
        },
    )


Distro = Annotated[Literal["humble", "jazzy"], Query(description="the ROS 2 message definitions in the bag")]


@bag_router.get("/export.mcap", response_class=Response, responses={200: {"content": {BAG_MEDIA["mcap"]: {}}}})
def export_mcap(session: SessionDep, distro: Distro = "humble") -> Response:
    """The scan as a ROS 2 bag (rosbag2, MCAP), from the journal: per view the depth image (32FC1 metres), camera
    info, /tf and joint states; the registered cloud (PointCloud2) and the surface (Marker). docs/bags.md. 409
    without a journal or a view."""
    return _bag(session, "mcap", distro)


@bag_router.get("/export.db3", response_class=Response, responses={200: {"content": {BAG_MEDIA["db3"]: {}}}})
def export_db3(session: SessionDep, distro: Distro = "humble") -> Response:
    """The same bag as ``export.mcap`` in rosbag2's SQLite 3 storage."""
    return _bag(session, "db3", distro)


routers = [router, bag_router]
