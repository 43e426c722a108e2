"""Reading and setting the cameras of the browsers connected to the viser server."""

from __future__ import annotations

from typing import Any

import numpy as np
import viser


def set_camera(server: viser.ViserServer, position: Any, look_at: Any) -> int:
    """Point every connected client's camera from ``position`` at ``look_at`` (z up), and the initial
    camera of clients that connect later. Returns the number of clients moved."""
    server.initial_camera.position = tuple(np.asarray(position, dtype=float))
    server.initial_camera.look_at = tuple(np.asarray(look_at, dtype=float))
    clients = list(server.get_clients().values())
    for client in clients:
        with client.atomic():
            client.camera.up_direction = (0.0, 0.0, 1.0)
            client.camera.position = np.asarray(position, dtype=float)
            client.camera.look_at = np.asarray(look_at, dtype=float)
    return len(clients)


def client_cameras(server: viser.ViserServer) -> list[dict[str, Any]]:
    """The camera each connected client reported last: OpenCV pose (``wxyz``, ``position``: camera to
    world), ``look_at``, vertical ``fov`` (rad) and the canvas size in device pixels."""
    out = []
    for cid, client in server.get_clients().items():
        cam = client.camera
        if cam.update_timestamp == 0.0:
            continue
        out.append(
            {
                "client_id": cid,
                "position": np.asarray(cam.position).tolist(),
                "wxyz": np.asarray(cam.wxyz).tolist(),
                "look_at": np.asarray(cam.look_at).tolist(),
                "fov": float(cam.fov),
                "image_width": int(cam.image_width),
                "image_height": int(cam.image_height),
                "timestamp": float(cam.update_timestamp),
            }
        )
    return out


FRAMING_DISTANCE = 0.85
"""How far a framing camera is from what it looks at, metres: the object fills a good share of the view and the
candidates' hemisphere (radius about 0.45 m) still shows."""
FRAMING_ELEVATION_DEG = 32.0
"""How high it looks down from, degrees above the horizon."""
FRAMING_OFFSET_DEG = 35.0
"""How far round from straight opposite the arm's mount it stands, degrees (the arm shows beside the object, not
behind it)."""
FRAMING_FOV_DEG = 50.0
"""Its vertical field of view, degrees (viser's default 75 made the object a speck)."""
FRAMING_LOOK_AT = (0.0, 0.0, 0.07)
"""What it looks at: the middle of an object on the plate, metres."""


def framing(mount_xy: tuple[float, float] | None) -> tuple[tuple[float, float, float], tuple[float, float, float]]:
    """(eye, look_at) of a camera on the object from the side away from the arm's mount at ``mount_xy`` (the
    scene's frame, metres; its azimuth changes as the plate turns), or from the front-right without an arm."""
    import math

    if mount_xy is None or math.hypot(*mount_xy) < 1e-6:
        azimuth = math.radians(-35.0)
    else:
        azimuth = math.atan2(mount_xy[1], mount_xy[0]) + math.pi + math.radians(FRAMING_OFFSET_DEG)
    e = math.radians(FRAMING_ELEVATION_DEG)
    x, y, z = FRAMING_LOOK_AT
    d = FRAMING_DISTANCE
    eye = (x + d * math.cos(e) * math.cos(azimuth), y + d * math.cos(e) * math.sin(azimuth), z + d * math.sin(e))
    return eye, FRAMING_LOOK_AT
