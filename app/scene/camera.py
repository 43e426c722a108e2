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
