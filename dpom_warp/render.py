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
    ground-truth boxes (dashed); right the occupancy map rho* on the ground grid with
    detections (circles), ground truth (crosses) and the camera position."""
    fig, (ax_d, ax_m) = plt.subplots(1, 2, figsize=(13, 5.2), dpi=80,
                                     gridspec_kw={"width_ratios": [1.15, 1]})
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
    m = ax_m.imshow(rho_map, origin="lower", extent=(x0, x1, y0, y1), cmap="magma", vmin=0, vmax=1,
                    interpolation="nearest")
    fig.colorbar(m, ax=ax_m, fraction=0.04, label="rho*")
    if truth:
        ax_m.scatter([o["x"] for o in truth], [o["y"] for o in truth], marker="x", c="lime", s=60,
                     label="ground truth")
    if detections:
        ax_m.scatter([d.x for d in detections], [d.y for d in detections], facecolors="none",
                     edgecolors="cyan", s=140, lw=2, label="detections")
    ax_m.plot(*camera_xy, marker="^", color="white", ms=10, mec="black", ls="none", label="camera")
    lo_y = min(y0, camera_xy[1] - 0.3)
    ax_m.set_xlim(min(x0, camera_xy[0] - 0.3), max(x1, camera_xy[0] + 0.3))
    ax_m.set_ylim(lo_y, y1)
    ax_m.set_facecolor("#202020")
    ax_m.set_xlabel("x (m)")
    ax_m.set_ylabel("y (m)")
    ax_m.set_aspect("equal")
    ax_m.set_title("occupancy map (top view)")
    ax_m.legend(loc="upper right", fontsize=8, framealpha=0.6)
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)
