"""A rig's frame picture (issue 61): the first camera's depth with the detections' boxes beside
the one map (render.frame_picture, the map's grey where no camera sees, with several cameras
each one's field of view outlined in its colour and named at its mark), and below it every
other camera's depth with the same detections' boxes as that camera sees them, each named."""

from __future__ import annotations

import io
import numpy as np
from PIL import Image, ImageDraw

from .render import BG, INK, PAD, PANEL_H, colour_image, encode_png, font, frame_picture


def depth_panel(depth: np.ndarray, boxes: list, title: str, vmax: float | None) -> Image.Image:
    """A camera's depth frame (PANEL_H high) with `boxes` (image rectangles) and its title above."""
    depth = np.asarray(depth, np.float32)
    seen = depth > 0
    top = vmax or (float(np.percentile(depth[seen], 99)) if seen.any() else 1.0)
    h, w = depth.shape
    zoom = PANEL_H / h
    img = colour_image(depth, 0.0, top, "turbo", ~seen).convert("RGB")
    img = img.resize((max(1, int(round(w * zoom))), PANEL_H), Image.NEAREST)
    panel = Image.new("RGB", (img.width + 2 * PAD, PANEL_H + 2 * PAD), BG)
    panel.paste(img, (PAD, PAD))
    draw = ImageDraw.Draw(panel)
    draw.text((PAD, PAD - 6), title, fill=INK, font=font(13), anchor="ld")
    for box in boxes:
        u0, v0, u1, v1 = (np.asarray(box, float) + [-0.5, -0.5, 0.5, 0.5]) * zoom
        draw.rectangle((PAD + u0, PAD + v0, PAD + u1, PAD + v1), outline=(255, 255, 255), width=2)
    return panel


def rig_picture(depths: list, rho_map: np.ndarray, cfg, rig, detections: list, truth=None,
                title: str = "", tracks=None, overlay: dict | None = None) -> bytes:
    """A PNG file's bytes of a rig's frame: `depths` one a camera, `rig` their full-resolution
    geometry.RigGeometry, `detections` located on the first camera's geometry (their boxes its
    rectangles); `tracks` (outputs.ShownTracks) on the first camera's panel and the map."""
    names, geometries = cfg.camera_names, rig.parts
    in_view = rig.rect_area > 0  # in view of any camera
    truth = None if truth is None else [{k: v for k, v in o.items() if k != "bbox"} for o in truth]  # (boxes: one camera's)
    main = Image.open(io.BytesIO(frame_picture(
        depths[0] if depths[0] is not None else np.zeros(geometries[0].rays.shape[:2]), rho_map, cfg.grid, detections,
        np.array([g.centre[:2] for g in geometries]), truth, f"{title}  camera {names[0]}",
        in_view=in_view, tracks=tracks, trail=cfg.tracking.trail, overlay=overlay,
        views=[(n, g.rect_area > 0) for n, g in zip(names, geometries)] if len(geometries) > 1 else None)))
    panels = []
    for name, depth, g in zip(names[1:], depths[1:], geometries[1:]):
        boxes = [g.rect[d.k] for d in detections if g.rect_area[d.k] > 0]
        none = depth is None  # no frame of this camera here: inferred from the others
        panels.append(depth_panel(np.zeros((g.rays.shape[0], g.rays.shape[1])) if none else depth, [] if none else boxes,
                                  f"camera {name}{' (no frame)' if none else ''}", None))
    width = max([main.width, sum(p.width for p in panels)])
    canvas = Image.new("RGB", (width, main.height + (max(p.height for p in panels) if panels else 0)), BG)
    canvas.paste(main.convert("RGB"), (0, 0))
    x = 0
    for p in panels:
        canvas.paste(p, (x, main.height))
        x += p.width
    return encode_png(np.asarray(canvas))

