"""Result pictures: the depth frame with detection boxes beside the occupancy map.

Drawn with Pillow on NumPy colour tables (matplotlib's turbo and magma, sampled once), so a
picture costs a few milliseconds instead of the ~0.3 s of a matplotlib figure: at real-time
frame rates the pictures must not cost more than the inference.
"""

from __future__ import annotations

import struct
import tempfile
import zlib
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from PIL import Image, ImageDraw, ImageFont


BG = (255, 255, 255)
INK = (20, 20, 20)
PANEL_H = 424  # height of every panel, pixels
PAD = 36  # margin around panels (titles above, axis labels below)
BAR_W = 14  # colour bar width


def encode_png(rgb: np.ndarray, level: int = 1) -> bytes:
    """A PNG file's bytes of an (H, W, 3) uint8 image: 8-bit RGB, every row unfiltered, one
    zlib stream at `level` by zlib's compress. Pillow's writer chooses a filter per row, which
    on these flat plots costs more than it saves (`python -m bench.pictures`). zlib releases
    the GIL while it compresses and gives the same bytes for the same image whatever the
    thread or process: runs that resume, share frames between processes or run on Ray must
    write a one-process run's files byte for byte. (Intel's ISA-L deflated ~4x faster, but
    once wrote a different stream for the same image on CI, with pictures encoded on two
    threads.)"""
    rgb = np.ascontiguousarray(rgb, dtype=np.uint8)
    h, w, channels = rgb.shape
    if channels != 3:
        raise ValueError(f"encode_png: expected an (H, W, 3) image, found {rgb.shape}")
    rows = np.zeros((h, 3 * w + 1), np.uint8)  # each row: filter type 0 (None), then its bytes
    rows[:, 1:] = rgb.reshape(h, 3 * w)

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    header = struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)  # 8 bits, RGB, deflate, no interlace
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", header)
            + chunk(b"IDAT", zlib.compress(rows.tobytes(), level)) + chunk(b"IEND", b""))


@lru_cache(maxsize=None)
def colour_table(name: str) -> np.ndarray:
    """(256, 3) uint8 samples of a matplotlib colour map."""
    from matplotlib import colormaps

    return (colormaps[name](np.linspace(0.0, 1.0, 256))[:, :3] * 255 + 0.5).astype(np.uint8)


@lru_cache(maxsize=None)
def font(size: int = 12):
    try:
        return ImageFont.load_default(size=size)
    except TypeError:  # Pillow < 10.1: a fixed bitmap font
        return ImageFont.load_default()


@lru_cache(maxsize=None)
def colour_words(name: str) -> np.ndarray:
    """(256,) uint32 of a colour table, each colour's bytes R, G, B, 0 in memory order: one
    4-byte gather per pixel instead of a (H, W, 3) fancy index (~6x faster on a depth frame)."""
    words = np.zeros(256, np.uint32)
    words.view(np.uint8).reshape(256, 4)[:, :3] = colour_table(name)
    return words


def colour_words_of(values: np.ndarray, vmin: float, vmax: float, cmap: str, missing=None) -> np.ndarray:
    """(H, W) uint32 colour words (colour_words) of `values`; `missing` (mask) black."""
    scaled = np.clip((values - vmin) * np.float32(255.0 / max(vmax - vmin, 1e-12)), 0.0, 255.0)
    words = colour_words(cmap)[np.nan_to_num(scaled).astype(np.uint8)]
    if missing is not None:
        words[missing] = 0
    return words


def colourise(values: np.ndarray, vmin: float, vmax: float, cmap: str, missing=None) -> np.ndarray:
    """(H, W, 3) uint8 of `values` through a colour table; `missing` (mask) drawn black."""
    words = colour_words_of(values, vmin, vmax, cmap, missing)
    return np.ascontiguousarray(words.view(np.uint8).reshape(*values.shape, 4)[..., :3])


def colour_image(values: np.ndarray, vmin: float, vmax: float, cmap: str, missing=None) -> Image.Image:
    """colourise's colours as a Pillow image (RGBX, no copy of the words: pasting it on an RGB
    canvas converts it in C, where a (H, W, 3) copy of the words costs more than the lookup)."""
    words = np.ascontiguousarray(colour_words_of(values, vmin, vmax, cmap, missing))
    h, w = words.shape
    return Image.frombuffer("RGBX", (w, h), words, "raw", "RGBX", 0, 1)


def dashed_rectangle(draw: ImageDraw.ImageDraw, box, fill, dash: int = 5, width: int = 1):
    u0, v0, u1, v1 = box
    for a, b, fixed, horizontal in ((u0, u1, v0, True), (u0, u1, v1, True),
                                    (v0, v1, u0, False), (v0, v1, u1, False)):
        for s in range(int(a), int(b) + 1, 2 * dash):
            e = min(s + dash, b)
            draw.line((s, fixed, e, fixed) if horizontal else (fixed, s, fixed, e), fill=fill,
                      width=width)


@lru_cache(maxsize=None)
def bar_image(cmap: str, h: int) -> Image.Image:
    """The colour bar's gradient, `h` rows from the top colour down (drawn once per size)."""
    table = colour_table(cmap)
    rows = table[(np.arange(h)[::-1] * 255) // max(h - 1, 1)]
    return Image.fromarray(np.repeat(rows[:, None, :], BAR_W + 1, axis=1))


def colour_bar(canvas: Image.Image, draw: ImageDraw.ImageDraw, x: int, y: int, h: int, cmap: str,
               label: str):
    """A colour bar's gradient, outline and label (its values: bar_values)."""
    canvas.paste(bar_image(cmap, h), (x, y))
    draw.rectangle((x, y, x + BAR_W, y + h - 1), outline=INK)
    draw.text((x + BAR_W + 3, y - 4), label, fill=INK, font=font(11), anchor="ld")


def bar_values(draw: ImageDraw.ImageDraw, x: int, y: int, h: int, vmin: float, vmax: float):
    """The bottom, middle and top values beside the colour bar at (x, y), `h` high."""
    for frac in (0.0, 0.5, 1.0):
        yy = y + h - 1 - frac * (h - 1)
        draw.text((x + BAR_W + 3, yy), f"{vmin + frac * (vmax - vmin):.3g}", fill=INK, font=font(11), anchor="lm")


OUT_OF_VIEW = (58, 64, 76)  # map cells the camera does not see (a blue-grey no text or map colour has)


class MapPanel:
    """A top or side view of a map in world coordinates, drawn at a fixed scale."""

    def __init__(self, image: np.ndarray, extent, view, scale: float, outside=None):
        self.image, self.extent, self.view, self.scale = image, extent, view, scale
        self.outside = outside  # cells out of the camera's view: drawn as the panel's grey
        x0, x1, y0, y1 = view
        self.w = int(round((x1 - x0) * scale))
        self.h = int(round((y1 - y0) * scale))

    def to_px(self, x, y, ox, oy):
        x0, _, _, y1 = self.view
        return ox + (x - x0) * self.scale, oy + (y1 - y) * self.scale

    def frame(self, draw: ImageDraw.ImageDraw, ox: int, oy: int, title: str, ylabel: str):
        """What does not change from frame to frame: the panel's ground, outline, axes and titles."""
        draw.rectangle((ox, oy, ox + self.w - 1, oy + self.h - 1), fill=(32, 32, 32), outline=INK)
        f = font(11)
        vx0, vx1, vy0, vy1 = self.view
        for t in np.arange(np.ceil(vx0), np.floor(vx1) + 1):
            px, _ = self.to_px(t, vy0, ox, oy)
            draw.line((px, oy + self.h, px, oy + self.h + 4), fill=INK)
            draw.text((px, oy + self.h + 6), f"{t + 0.0:g}", fill=INK, font=f, anchor="mt")
        for t in np.arange(np.ceil(vy0), np.floor(vy1) + 1):
            _, py = self.to_px(vx0, t, ox, oy)
            draw.line((ox - 4, py, ox, py), fill=INK)
            draw.text((ox - 6, py), f"{t + 0.0:g}", fill=INK, font=f, anchor="rm")
        draw.text((ox + self.w / 2, oy + self.h + 20), "x (m)", fill=INK, font=f, anchor="mt")
        draw.text((ox - 22, oy - 4), ylabel, fill=INK, font=f, anchor="ld")
        draw.text((ox + self.w / 2, oy - 8), title, fill=INK, font=font(13), anchor="md")

    def paste(self, canvas: Image.Image, draw: ImageDraw.ImageDraw, ox: int, oy: int):
        """The map itself, inside the panel that `frame` drew (its outline drawn again on top)."""
        x0, x1, y0, y1 = self.extent
        a = self.to_px(x0, y1, ox, oy)
        b = self.to_px(x1, y0, ox, oy)
        size = (max(1, int(round(b[0] - a[0]))), max(1, int(round(b[1] - a[1]))))
        rgb = colourise(self.image[::-1], 0.0, 1.0, "magma")  # row 0 = lowest y: flip for the picture
        if self.outside is not None:
            rgb[self.outside[::-1]] = OUT_OF_VIEW
        canvas.paste(Image.fromarray(rgb).resize(size, Image.NEAREST), (int(round(a[0])), int(round(a[1]))))
        draw.rectangle((ox, oy, ox + self.w - 1, oy + self.h - 1), outline=INK)

    def outline(self, draw, ox, oy, mask: np.ndarray, colour) -> None:
        """The edge of `mask` (the map's shape, True inside) drawn along its cells' sides."""
        x0, x1, y0, y1 = self.extent
        ny, nx = mask.shape
        dx, dy = (x1 - x0) / nx, (y1 - y0) / ny
        padded = np.pad(np.asarray(mask, bool), 1)
        for j, i in np.argwhere(padded[1:-1, 1:] != padded[1:-1, :-1]):  # a side between columns i - 1 and i
            draw.line((*self.to_px(x0 + i * dx, y0 + j * dy, ox, oy), *self.to_px(x0 + i * dx, y0 + (j + 1) * dy, ox, oy)),
                      fill=colour, width=2)
        for j, i in np.argwhere(padded[1:, 1:-1] != padded[:-1, 1:-1]):  # a side between rows j - 1 and j
            draw.line((*self.to_px(x0 + i * dx, y0 + j * dy, ox, oy), *self.to_px(x0 + (i + 1) * dx, y0 + j * dy, ox, oy)),
                      fill=colour, width=2)

    def marks(self, draw, ox, oy, truth, dets):
        for x, y in truth:
            px, py = self.to_px(x, y, ox, oy)
            draw.line((px - 5, py - 5, px + 5, py + 5), fill=(0, 255, 0), width=2)
            draw.line((px - 5, py + 5, px + 5, py - 5), fill=(0, 255, 0), width=2)
        for x, y in dets:
            px, py = self.to_px(x, y, ox, oy)
            draw.ellipse((px - 7, py - 7, px + 7, py + 7), outline=(0, 255, 255), width=2)


def place_label(draw: ImageDraw.ImageDraw, label: str, at, taken: list, bounds) -> tuple:
    """The rectangle of a label drawn with its lower left at `at`, moved up (then down) by
    whole label heights until it covers none of the labels in `taken` and stays inside
    `bounds`; it is added to `taken`."""
    x0, y0, x1, y1 = draw.textbbox(at, label, font=font(11), anchor="lb")
    w, h = x1 - x0 + 2, y1 - y0 + 2
    left = min(max(at[0], bounds[0]), bounds[2] - w)
    base = at[1]
    for k in [0] + [s * i for i in range(1, 20) for s in (-1, 1)]:
        top = base - h + k * h
        rect = (left, top, left + w, top + h)
        inside = bounds[1] <= top and top + h <= bounds[3]
        if inside and not any(rect[0] < r[2] and r[0] < rect[2] and rect[1] < r[3] and r[1] < rect[3]
                              for r in taken):
            break
    else:
        rect = (left, max(bounds[1], base - h), left + w, max(bounds[1], base - h) + h)
    taken.append(rect)
    return rect


@lru_cache(maxsize=None)
def track_colour(track_id: int) -> tuple:
    """A track's colour: matplotlib's tab20, by identity."""
    table = colour_table("tab20")
    c = table[(track_id * 7) % 20 * 255 // 19]
    return tuple(int(v) for v in c)


def fade(colour, age: float, towards=(32, 32, 32)) -> tuple:
    """`colour` mixed towards the map's background by `age` (0: as is, 1: gone)."""
    return tuple(int(round(c + (b - c) * age)) for c, b in zip(colour, towards))


def track_identities(detections, tracks) -> dict:
    """Detection index -> the identity of the track at it: a track not bridged in this frame
    whose position is within 0.25 m of its nearest detection (on the ground plane)."""
    ident = {}
    for tr in tracks:
        if tr["bridged"] or not detections:
            continue
        x, y = tr["trail"][-1][0], tr["trail"][-1][1]  # where it is now
        k = min(range(len(detections)), key=lambda i: np.hypot(detections[i].x - x, detections[i].y - y))
        if np.hypot(detections[k].x - x, detections[k].y - y) < 0.25:
            ident[k] = tr["id"]
    return ident


def draw_tracks(draw, panel: MapPanel, ox, oy, tracks, trail: int, side: bool = False):
    """Each track's trail (the last `trail` frames, fading with age) and its identity on a
    map panel; `side`: the panel shows (x, z)."""
    for tr in tracks:
        colour = track_colour(tr["id"])
        pts = [panel.to_px(p[0], p[2] if side else p[1], ox, oy) for p in tr["trail"]]
        n = len(pts)
        for i in range(1, n):  # the newest segment in the track's colour, older ones fading
            draw.line((*pts[i - 1], *pts[i]), fill=fade(colour, 0.85 * (n - 1 - i) / max(1, trail)), width=2)
        if pts:
            px, py = pts[-1]
            draw.text((px + 8, py - 8), str(tr["id"]), fill=colour, font=font(11), anchor="lb")


def frame_picture(depth_m, rho_map, grid, detections, camera_xy, truth=None, title="",
                  z_max=None, in_view=None, tracks=None, trail: int = 30, overlay: dict | None = None,
                  views: list | None = None) -> bytes:
    """A PNG file's bytes: left the depth frame with detection boxes (solid, with rho*) and
    ground-truth boxes (dashed); right the occupancy map rho* seen from above, with
    detections (circles), ground truth (crosses) and the camera position; for a voxel grid
    also a side view (maximum over y). `in_view` (map-shaped bool): the locations the camera
    sees; the others are drawn grey, so the map shows the camera's footprint (a wedge at eye
    level, the floor below it from the ceiling). `tracks`: the tracks of this frame, dicts of
    id, box (image rectangle), bridged (no detection: the box is drawn dashed) and trail (its
    positions over the last `trail` frames, this one last): identities on the boxes, fading
    trails on the maps. What is the same in every frame of a run (axes, titles, colour bars,
    legend) is drawn once per layout (picture_template) and copied. `overlay`: zones and lines
    on the top map ({"zones": [(polygon (n, 2), label)], "lines": [(from, to, label)]},
    zone_tables.ZoneTables' of the frame: each zone's count, each line's crossings so far).
    `views` (a rig's): (name, map-shaped bool) a camera, in camera_xy's order: each camera's
    field of view outlined on the top map in its colour (VIEW_INKS), its name by its mark."""
    voxel = rho_map.ndim == 3
    has_truth, truth = truth is not None, truth or []
    depth = np.asarray(depth_m, dtype=np.float32)
    seen = depth > 0
    vmax = z_max or (float(np.percentile(depth[seen], 99)) if seen.any() else 1.0)
    h, w = depth.shape
    zoom = PANEL_H / h
    depth_img = colour_image(depth, 0.0, vmax, "turbo", ~seen)
    if zoom != 1.0:
        depth_img = depth_img.resize((max(1, int(round(w * zoom))), PANEL_H), Image.NEAREST)

    x0, x1 = grid.x[0], grid.x[0] + grid.shape[-1] * grid.x[2]
    y0, y1 = grid.y[0], grid.y[0] + grid.shape[-2] * grid.y[2]
    cams = np.asarray(camera_xy, float).reshape(-1, 2)  # a rig's: every camera's, each drawn
    view = (min(x0, cams[:, 0].min() - 0.3), max(x1, cams[:, 0].max() + 0.3), min(y0, cams[:, 1].min() - 0.3),
            max(y1, cams[:, 1].max() + 0.3))
    scale = PANEL_H / (view[3] - view[2])
    seen_top = seen_side = None
    if in_view is not None:
        in_view = np.asarray(in_view, bool).reshape(rho_map.shape)
        seen_top, seen_side = (~in_view.any(axis=0), ~in_view.any(axis=1)) if voxel else (~in_view, None)
    top = MapPanel(rho_map.max(axis=0) if voxel else rho_map, (x0, x1, y0, y1), view, scale, seen_top)
    panels = [top]
    if voxel:
        z0, z1 = grid.z[0], grid.z[0] + grid.shape[0] * grid.z[2]
        panels.append(MapPanel(rho_map.max(axis=1), (x0, x1, z0, z1), (view[0], view[1], z0, z1), scale,
                               seen_side))
    layout = PictureLayout(depth_img.width, tuple((p.extent, p.view, p.scale) for p in panels), has_truth,
                           tracks is not None)
    canvas = picture_template(layout).copy()
    draw = ImageDraw.Draw(canvas)

    ox, oy = PAD, PAD
    canvas.paste(depth_img, (ox, oy))
    for o in truth:
        if "bbox" in o:
            u0, v0, u1, v1 = (np.asarray(o["bbox"], float) + [-0.5, -0.5, 0.5, 0.5]) * zoom
            dashed_rectangle(draw, (ox + u0, oy + v0, ox + u1, oy + v1), (0, 255, 0))
    boxes = [(np.asarray(d.box, float) + [-0.5, -0.5, 0.5, 0.5]) * zoom for d in detections]
    for u0, v0, u1, v1 in boxes:
        draw.rectangle((ox + u0, oy + v0, ox + u1, oy + v1), outline=(255, 255, 255), width=2)
    ident = track_identities(detections, tracks or [])
    for tr in tracks or []:
        if tr["id"] not in ident.values():  # bridged: where the tracker holds the person, hidden or missed
            u0, v0, u1, v1 = (np.asarray(tr["box"], float) + [-0.5, -0.5, 0.5, 0.5]) * zoom
            dashed_rectangle(draw, (ox + u0, oy + v0, ox + u1, oy + v1), track_colour(tr["id"]), width=2)
            draw.text((ox + u0 + 2, oy + v0 + 2), f"#{tr['id']}", fill=track_colour(tr["id"]),
                      font=font(11), anchor="lt")
    taken = []
    for i, (d, (u0, v0, u1, v1)) in enumerate(zip(detections, boxes)):
        label = f"#{ident[i]} {d.rho:.2f}" if i in ident else f"{d.rho:.2f}"
        tb = place_label(draw, label, (ox + u0, oy + v0 - 2), taken, (ox, oy, ox + depth_img.width, oy + PANEL_H))
        draw.rectangle(tb, fill=(0, 0, 0))
        draw.text((tb[0] + 1, tb[3] - 1), label, fill=(255, 255, 255), font=font(11), anchor="lb")
    draw.rectangle((ox - 1, oy - 1, ox + depth_img.width, oy + PANEL_H), outline=INK)
    draw.text((ox + depth_img.width / 2, oy - 8), f"{title}  ({len(detections)} detections)",
              fill=INK, font=font(13), anchor="md")
    bar_values(draw, ox + depth_img.width + 8, oy + 16, PANEL_H - 32, 0.0, vmax)

    ox += depth_img.width + BAR_SPACE + PAD + 10
    top.paste(canvas, draw, ox, oy)
    top.marks(draw, ox, oy, [(o["x"], o["y"]) for o in truth], [(d.x, d.y) for d in detections])
    if tracks:
        draw_tracks(draw, top, ox, oy, tracks, trail)
    if overlay:
        draw_overlay(draw, top, ox, oy, overlay)
    draw_cameras(draw, top, ox, oy, cams, views, rho_map.shape)
    if voxel:
        side = panels[1]
        ox += top.w + PAD + 10
        side.paste(canvas, draw, ox, oy)
        side.marks(draw, ox, oy, [(o["x"], o.get("z", 0.0)) for o in truth], [(d.x, d.z) for d in detections])
        if tracks:
            draw_tracks(draw, side, ox, oy, tracks, trail, side=True)
    return encode_png(np.asarray(canvas))


BAR_SPACE = BAR_W + 44  # a colour bar with its values
ZONE_INK, LINE_INK = (80, 200, 255), (120, 255, 120)
VIEW_INKS = ((255, 64, 160), (150, 220, 60), (90, 140, 255), (255, 110, 90), (60, 220, 200), (200, 120, 255))  # a rig's cameras (no other colour of the pictures)


def draw_cameras(draw: ImageDraw.ImageDraw, top: MapPanel, ox: int, oy: int, cams: np.ndarray,
                 views: list | None, map_shape: tuple) -> None:
    """Each camera's mark on the top map; with `views` (frame_picture's), each camera's field of
    view outlined in its colour first and its name beside its mark."""
    for k, (name, mask) in enumerate(views or []):
        seen_map = np.asarray(mask, bool).reshape(map_shape)
        top.outline(draw, ox, oy, seen_map.any(axis=0) if len(map_shape) == 3 else seen_map,
                    VIEW_INKS[k % len(VIEW_INKS)])
    for k, cam in enumerate(cams):
        cx, cy = top.to_px(cam[0], cam[1], ox, oy)
        draw.polygon([(cx, cy - 8), (cx - 7, cy + 5), (cx + 7, cy + 5)], fill=(255, 255, 255), outline=INK)
        if views and k < len(views):
            draw.text((cx + 9, cy), views[k][0], fill=VIEW_INKS[k % len(VIEW_INKS)], font=font(11), anchor="lm")


def draw_overlay(draw: ImageDraw.ImageDraw, panel: MapPanel, ox: int, oy: int, overlay: dict) -> None:
    """Zones (outlines, their label at their centre) and lines (an arrow from `from` to `to`,
    their label at the middle) on a top map panel."""
    for polygon, label in overlay.get("zones", ()):
        pts = [panel.to_px(x, y, ox, oy) for x, y in polygon]
        draw.line(pts + pts[:1], fill=ZONE_INK, width=2)
        cx, cy = np.mean(pts, axis=0)
        draw.text((cx, cy), label, fill=ZONE_INK, font=font(11), anchor="mm")
    for start, end, label in overlay.get("lines", ()):
        (ax, ay), (bx, by) = panel.to_px(*start, ox, oy), panel.to_px(*end, ox, oy)
        draw.line((ax, ay, bx, by), fill=LINE_INK, width=2)
        u = np.array([bx - ax, by - ay]) / max(np.hypot(bx - ax, by - ay), 1e-9)
        tip = np.array([bx, by])
        for turn in (0.5, -0.5):  # the arrow's head at `to`
            c, s = np.cos(np.pi - turn), np.sin(np.pi - turn)
            wing = tip + 9 * np.array([c * u[0] - s * u[1], s * u[0] + c * u[1]])
            draw.line((bx, by, *wing), fill=LINE_INK, width=2)
        draw.text(((ax + bx) / 2 + 4, (ay + by) / 2), label, fill=LINE_INK, font=font(11), anchor="lm")


@dataclass(frozen=True)
class PictureLayout:
    """What decides a picture's unchanging parts: the depth panel's width, each map panel's
    (extent, view, scale), whether the legend shows ground truth and tracks."""
    depth_width: int
    panels: tuple
    truth: bool
    tracks: bool


@lru_cache(maxsize=16)
def picture_template(layout: PictureLayout) -> Image.Image:
    """The canvas of a picture with what `layout` alone decides drawn on it: the map panels'
    grounds, axes and titles, the colour bars (the depth bar's values change: drawn per
    frame) and the legend. Drawn once per layout (text is most of a picture's drawing) and
    copied for every frame; never drawn on itself."""
    panels = [MapPanel(None, *p) for p in layout.panels]
    voxel = len(panels) == 2
    width = PAD + layout.depth_width + BAR_SPACE + sum(PAD + 10 + p.w for p in panels) + BAR_SPACE
    height = PAD + PANEL_H + PAD + 8
    canvas = Image.new("RGB", (int(width), height), BG)
    draw = ImageDraw.Draw(canvas)
    ox, oy = PAD, PAD
    colour_bar(canvas, draw, ox + layout.depth_width + 8, oy + 16, PANEL_H - 32, "turbo", "depth (m)")
    ox += layout.depth_width + BAR_SPACE + PAD + 10
    panels[0].frame(draw, ox, oy, "occupancy map (top view" + (", max over z)" if voxel else ")"), "y (m)")
    if voxel:
        ox += panels[0].w + PAD + 10
        panels[1].frame(draw, ox, oy, "side view (max over y)", "z (m)")
    ox += panels[-1].w
    colour_bar(canvas, draw, ox + 10, oy + 16, PANEL_H - 32, "magma", "rho*")
    bar_values(draw, ox + 10, oy + 16, PANEL_H - 32, 0.0, 1.0)
    legend = ([((0, 255, 0), "x ground truth")] if layout.truth else []) + [
        ((0, 255, 255), "o detections"), ((255, 255, 255), "^ camera")] + (
        [((180, 120, 40), "#n track (dashed: bridged)")] if layout.tracks else [])
    for i, (c, text) in enumerate(legend):
        draw.text((PAD + 4 + 120 * i, height - 12), text, fill=tuple(int(v * 0.7) for v in c) if c != (255, 255, 255) else INK,
                  font=font(11), anchor="lm")
    return canvas


def ply_files(stem: str, depth, geometry, dets, cfg) -> dict[str, bytes]:
    """For Open3D's viewer: ply/<stem>_points.ply (the frame's points, world metres; a rig's:
    every camera's) and ply/<stem>_boxes.ply (the detected object boxes as a mesh), as bytes."""
    import open3d as o3d

    views = ([(d, g) for d, g in zip(depth, geometry.parts) if d is not None] if hasattr(geometry, "parts")
             else [(depth, geometry)])
    pts = np.concatenate([g.centre + d[d > 0][:, None].astype(np.float64) * g.rays[d > 0] for d, g in views])
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
    boxes = o3d.geometry.TriangleMesh()
    size = np.array([cfg.obj.width, cfg.obj.depth or cfg.obj.width, cfg.obj.height])
    for d in dets:
        b = o3d.geometry.TriangleMesh.create_box(*size)
        lift = 0.0 if cfg.grid.mode == "ground" else size[2] / 2
        boxes += b.translate(np.array([d.x, d.y, d.z - lift]) - np.array([size[0] / 2, size[1] / 2, 0]))
    with tempfile.TemporaryDirectory(prefix="dpom-warp-ply-") as tmp:
        points, mesh = Path(tmp) / "points.ply", Path(tmp) / "boxes.ply"
        o3d.io.write_point_cloud(str(points), cloud)
        o3d.io.write_triangle_mesh(str(mesh), boxes)
        return {f"ply/{stem}_points.ply": points.read_bytes(),
                f"ply/{stem}_boxes.ply": mesh.read_bytes()}
