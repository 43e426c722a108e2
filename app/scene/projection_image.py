"""A picture of what a candidate camera sees of the ellipsoids: the projected conics with their weights.

Frontier ellipses are red, occupied ones blue; the fill is stronger for a larger
depth-rank weight ``w = 0.5**rank``, and nearer ellipses are drawn over farther
ones. The TOP_LABELS nearest-ranked ellipses are labelled with their name (kind + index). Ellipsoids behind
the camera are skipped; one that straddles the image plane or contains the camera
is listed in the footer (it has no ellipse outline).
"""

from __future__ import annotations

import io
from typing import Any

import numpy as np
from numpy.typing import NDArray
from PIL import Image, ImageDraw, ImageFont

from app.serialize import ellipsoid_labels
from planner import Intrinsics, PlanResult
from planner.projection import FRONT, INSIDE, STRADDLE, project

FRONTIER_RGB = (235, 60, 40)
OCCUPIED_RGB = (40, 100, 235)
BACKGROUND = (24, 24, 28)


def ellipse_polygon(center: NDArray[np.float64], shape: NDArray[np.float64], n: int = 72) -> list[tuple[float, float]]:
    """Outline of ``{x : (x - center)^T shape^-1 (x - center) <= 1}`` as ``n`` pixel points."""
    w, V = np.linalg.eigh(0.5 * (shape + shape.T))
    L = V * np.sqrt(np.clip(w, 0.0, None))
    t = np.linspace(0.0, 2.0 * np.pi, n, endpoint=False)
    pts = center[None, :] + np.stack([np.cos(t), np.sin(t)], axis=1) @ L.T
    return [(float(x), float(y)) for x, y in pts]


TOP_LABELS = 8
"""Only the nearest-ranked ellipses are labelled (by name; weights are in the page's table), so many
ellipsoids stay legible."""


def _label(
    draw: ImageDraw.ImageDraw,
    font: ImageFont.FreeTypeFont | ImageFont.ImageFont,
    centers: NDArray[np.float64],
    tags: list[tuple[int, str]],
    W: int,
    H: int,
) -> None:
    """Write each tag at its ellipse centre, nearest ellipsoid first, skipping tags that would overlap."""
    placed: list[tuple[float, float, float, float]] = []
    for i, text in tags:
        cx, cy = centers[i]
        if not (0 <= cx < W and 0 <= cy < H):
            continue
        box = draw.textbbox((cx, cy), text, font=font, anchor="mm")
        if any(box[0] < b[2] and b[0] < box[2] and box[1] < b[3] and b[1] < box[3] for b in placed):
            continue
        placed.append(box)
        draw.text((cx, cy), text, font=font, anchor="mm", fill=(255, 255, 255, 255), stroke_width=2,
                  stroke_fill=(0, 0, 0, 255))  # fmt: skip


def render_projection(plan: PlanResult, index: int, intrinsics: Intrinsics) -> bytes:
    """PNG bytes of candidate ``index``'s image of ``plan.ellipsoids`` (size of ``intrinsics``)."""
    W, H = intrinsics.width, intrinsics.height
    candidate = plan.candidates[index]
    score = plan.scores[index]
    image = Image.new("RGB", (W, H), BACKGROUND)
    overlay = Image.new("RGBA", (W, H), (0, 0, 0, 0))
    draw = ImageDraw.Draw(overlay)
    size = max(11, H // 30)
    font = ImageFont.load_default(size=size)
    notes: list[str] = []
    E = len(plan.ellipsoids)
    if E:
        proj = project(plan.ellipsoids, [candidate.T_world_camera], intrinsics)
        ranks = np.asarray(score.ranks) if len(score.ranks) == E else np.zeros(E, dtype=np.int64)
        weights = np.asarray(score.weights) if len(score.weights) == E else np.ones(E)
        labels = ellipsoid_labels(plan)
        depth = proj.centers_camera[0, :, 2]
        tags: list[tuple[int, str]] = []
        for i in np.argsort(-depth):  # far first, near on top
            e = plan.ellipsoids[i]
            rgb = FRONTIER_RGB if e.kind == "frontier" else OCCUPIED_RGB
            status = int(proj.status[0, i])
            if status == FRONT:
                poly = ellipse_polygon(proj.ellipse_center[0, i], proj.ellipse_shape[0, i])
                alpha = int(40 + 150 * float(np.clip(weights[i], 0.0, 1.0)))
                draw.polygon(poly, fill=(*rgb, alpha), outline=(*rgb, 255))
                tags.append((int(i), str(labels[i])))
            elif status in (STRADDLE, INSIDE):
                what = "contains the camera" if status == INSIDE else "crosses the image plane"
                notes.append(f"{labels[i]} (rank {int(ranks[i])}, w={weights[i]:.3g}) {what}")
        top = sorted(tags, key=lambda t: ranks[t[0]])[:TOP_LABELS]  # the rest: the page's table
        _label(draw, font, proj.ellipse_center[0], top, W, H)
    image.paste(overlay, (0, 0), overlay)
    text = ImageDraw.Draw(image)
    header = (
        f"candidate {index}  F={score.score:.4g}  frontier={score.frontier:.4g}  occupied={score.occupied:.4g}"
        f"  {'eligible' if score.eligible else 'ineligible'}"
    )
    line = int(size * 1.3)
    text.rectangle((0, 0, W, line + 2), fill=(0, 0, 0))
    text.text((4, 2), header, fill=(255, 255, 255), font=font)
    text.text((4, line + 4), "frontier", fill=FRONTIER_RGB, font=font)
    text.text((4 + 6 * size, line + 4), "occupied", fill=OCCUPIED_RGB, font=font)
    for k, note in enumerate(notes[:6]):
        text.text((4, H - line * (k + 1)), note, fill=(230, 230, 230), font=font)
    buf = io.BytesIO()
    image.save(buf, format="PNG")
    return buf.getvalue()


ZBUFFER_COLORS = {
    "visible": (220, 40, 40),
    "hidden": (110, 40, 40),
    "occupied": (60, 110, 200),
    "none": (245, 245, 245),
}
"""Pixel colours of the z-buffer inspector image: frontier counted in V, frontier hidden behind occupied,
occupied only, nothing."""


def render_zbuffer(plan: PlanResult, index: int, intrinsics: Intrinsics, config: Any, resolution: float) -> bytes:
    """PNG of what ``projection-zbuffer`` counts for candidate ``index``: its raster (``zbuffer.width`` x
    ``zbuffer.height``) scaled up, visible frontier red, hidden frontier dark red, occupied blue; the legend
    and the share of frontier pixels that count are written under it."""
    from planner.visibility import zbuffer_image

    image = zbuffer_image(plan.ellipsoids, plan.candidates[index].T_world_camera, intrinsics, config, resolution)
    h, w = image.visible.shape
    rgb = np.empty((h, w, 3), dtype=np.uint8)
    rgb[:] = ZBUFFER_COLORS["none"]
    frontier = image.frontier_owner >= 0
    rgb[image.occupied_owner >= 0] = ZBUFFER_COLORS["occupied"]
    rgb[frontier & ~image.visible] = ZBUFFER_COLORS["hidden"]
    rgb[image.visible] = ZBUFFER_COLORS["visible"]
    scale = max(1, 480 // w)
    raster = Image.fromarray(rgb).resize((w * scale, h * scale), Image.Resampling.NEAREST)
    canvas = Image.new("RGB", (raster.width, raster.height + 36), "white")
    canvas.paste(raster, (0, 0))
    draw = ImageDraw.Draw(canvas)
    n_front, n_vis = int(frontier.sum()), int(image.visible.sum())
    draw.text(
        (6, raster.height + 4),
        f"candidate {index}: {n_vis} of {n_front} frontier pixels in front of every occupied one (red) count;"
        " dark red: hidden, blue: occupied",
        fill=(0, 0, 0),
        font=ImageFont.load_default(),
    )
    out = io.BytesIO()
    canvas.save(out, format="PNG")
    return out.getvalue()
