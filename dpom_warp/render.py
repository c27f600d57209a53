"""Result pictures: the depth frame with detection boxes beside the occupancy map."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.patches import Rectangle  # noqa: E402
import numpy as np  # noqa: E402

from .io import atomic_path  # noqa: E402


def frame_picture(path, depth_m, rho_map, grid, detections, camera_xy, truth=None, title="",
                  z_max=None):
    """Write a PNG: left the depth frame with detection boxes (solid, with rho*) and
    ground-truth boxes (dashed); right the occupancy map rho* seen from above, with
    detections (circles), ground truth (crosses) and the camera position; for a voxel grid
    also a side view (maximum over y)."""
    voxel = rho_map.ndim == 3
    fig, axes = plt.subplots(1, 3 if voxel else 2, figsize=(18 if voxel else 13, 5.2), dpi=80,
                             gridspec_kw={"width_ratios": [1.15, 1, 1] if voxel else [1.15, 1]})
    ax_d, ax_m = axes[0], axes[1]
    shown = np.where(depth_m > 0, depth_m, np.nan)
    vmax = z_max or (np.nanpercentile(shown, 99) if np.isfinite(shown).any() else 1.0)
    im = ax_d.imshow(shown, cmap="turbo", vmin=0, vmax=vmax, interpolation="nearest")
    ax_d.set_facecolor("black")
    fig.colorbar(im, ax=ax_d, fraction=0.04, label="depth (m)")
    for o in truth or []:
        if "bbox" in o:
            u0, v0, u1, v1 = o["bbox"]
            ax_d.add_patch(Rectangle((u0 - 0.5, v0 - 0.5), u1 - u0 + 1, v1 - v0 + 1, fill=False,
                                     ec="lime", ls="--", lw=1.2))
    for d in detections:
        u0, v0, u1, v1 = d.box
        ax_d.add_patch(Rectangle((u0 - 0.5, v0 - 0.5), u1 - u0 + 1, v1 - v0 + 1, fill=False,
                                 ec="white", lw=2))
        ax_d.text(u0, v0 - 3, f"{d.rho:.2f}", color="white", fontsize=9,
                  bbox={"fc": "black", "alpha": 0.6, "pad": 1, "lw": 0})
    ax_d.set_title(f"{title}  ({len(detections)} detections)")
    ax_d.set_xticks([])
    ax_d.set_yticks([])

    x0, x1 = grid.x[0], grid.x[0] + grid.shape[-1] * grid.x[2]
    y0, y1 = grid.y[0], grid.y[0] + grid.shape[-2] * grid.y[2]
    top = rho_map.max(axis=0) if voxel else rho_map
    _map_panel(fig, ax_m, top, (x0, x1, y0, y1), [(d.x, d.y) for d in detections],
               [(o["x"], o["y"]) for o in truth or []], "y (m)",
               "occupancy map (top view" + (", max over z)" if voxel else ")"))
    ax_m.plot(*camera_xy, marker="^", color="white", ms=10, mec="black", ls="none", label="camera")
    ax_m.set_xlim(min(x0, camera_xy[0] - 0.3), max(x1, camera_xy[0] + 0.3))
    ax_m.set_ylim(min(y0, camera_xy[1] - 0.3), y1)
    ax_m.legend(loc="upper right", fontsize=8, framealpha=0.6)
    if voxel:
        z0, z1 = grid.z[0], grid.z[0] + grid.shape[0] * grid.z[2]
        _map_panel(fig, axes[2], rho_map.max(axis=1), (x0, x1, z0, z1),
                   [(d.x, d.z) for d in detections], [(o["x"], o.get("z", 0.0)) for o in truth or []],
                   "z (m)", "side view (max over y)")
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def _map_panel(fig, ax, image, extent, dets, truth, ylabel, title):
    m = ax.imshow(image, origin="lower", extent=extent, cmap="magma", vmin=0, vmax=1,
                  interpolation="nearest")
    fig.colorbar(m, ax=ax, fraction=0.04, label="rho*")
    if truth:
        ax.scatter(*zip(*truth), marker="x", c="lime", s=60, label="ground truth")
    if dets:
        ax.scatter(*zip(*dets), facecolors="none", edgecolors="cyan", s=140, lw=2, label="detections")
    ax.set_facecolor("#202020")
    ax.set_xlabel("x (m)")
    ax.set_ylabel(ylabel)
    ax.set_aspect("equal")
    ax.set_title(title)
