"""How every 3D view of the workbench is lit: the live viewers, the offline recording and the arm demo.

viser's two default directional lights (no shadows) and a hemisphere light (white from above, grey from below)
in place of viser's image-based environment map. A browser without a GPU renders the scene in software
(SwiftShader; a VM, a remote desktop, the browser tests): there the environment map's first frame (prefiltering
its HDR image) took 7 CPU-seconds of the browser's GPU process and every later frame cost twice as much (a
4-view session at 1024x700: the first three frames 8.8 -> 1.7 CPU-s, a frame 0.6 -> 0.3 CPU-s). The hemisphere
light keeps the lit objects (candidate spheres, the arm, the surface) near the colours the environment map gave
them; on a GPU either costs nothing.
"""

from __future__ import annotations

from typing import Any

SKY_RGB = (255, 255, 255)
GROUND_RGB = (130, 130, 140)
"""The hemisphere light's colours from above and from below (+z is up)."""
HEMISPHERE_INTENSITY = 2.2


def configure_lighting(server: Any) -> None:
    """Light ``server``'s scene (a ``viser.ViserServer``) the workbench way: +z up, no environment map, viser's
    default lights without shadows, the hemisphere light ``/lights/hemisphere``."""
    scene = server.scene
    scene.set_up_direction("+z")
    scene.configure_environment_map(None)
    scene.configure_default_lights(enabled=True, cast_shadow=False)
    scene.add_light_hemisphere(
        "/lights/hemisphere",
        sky_color=SKY_RGB,
        ground_color=GROUND_RGB,
        intensity=HEMISPHERE_INTENSITY,
        position=(0.0, 0.0, 1.0),
    )
