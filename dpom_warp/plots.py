"""Evaluation figures (matplotlib): MODA against the match distance and the box overlap,
and precision-recall curves, several detectors on each."""

from __future__ import annotations

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from .io import atomic_path  # noqa: E402

PROTOCOLS = {"penalise_hidden": "hidden people penalised", "ignore_hidden": "hidden people not penalised"}


def save_figure(fig, path):
    """A figure written as a PNG, atomically, and closed."""
    fig.tight_layout()
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png")
    plt.close(fig)


def moda_figure(results: list[dict], path, key: str, xlabel: str):
    """MODA (solid) and MODP (dotted) against the gate, one panel per protocol."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), dpi=90, sharey=True)
    for ax, (protocol, title) in zip(axes, PROTOCOLS.items()):
        for i, r in enumerate(results):
            curve = r[protocol].get(key)
            if not curve:
                continue
            x = [c["gate"] for c in curve]
            line, = ax.plot(x, [c["moda"] for c in curve], marker="o", ms=4, label=f"{r['name']} MODA")
            ax.plot(x, [c["modp"] for c in curve], ls=":", color=line.get_color(), label=f"{r['name']} MODP")
        ax.set_title(title)
        ax.set_xlabel(xlabel)
        ax.grid(alpha=0.3)
        ax.set_ylim(min(0.0, ax.get_ylim()[0]), 1.02)
    axes[0].set_ylabel("score (best detection threshold per point)")
    axes[1].legend(fontsize=8, loc="lower left")
    save_figure(fig, path)


def pr_figure(results: list[dict], path, key: str, title: str):
    """Precision against recall over the detection threshold, average precision in the legend."""
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), dpi=90, sharey=True)
    for ax, (protocol, sub) in zip(axes, PROTOCOLS.items()):
        for r in results:
            pr = r[protocol].get(key)
            if not pr or not pr["points"]:
                continue
            ax.plot([p["recall"] for p in pr["points"]], [p["precision"] for p in pr["points"]],
                    drawstyle="steps-post", label=f"{r['name']} (AP {pr['ap']:.3f})")
        ax.set_title(f"{title}, {sub}")
        ax.set_xlabel("recall")
        ax.set_xlim(0, 1.02)
        ax.set_ylim(0, 1.02)
        ax.grid(alpha=0.3)
        if ax.get_lines():  # (a run with no detection has no curve to name)
            ax.legend(fontsize=8, loc="lower left")
        else:
            ax.text(0.5, 0.5, "no detections", ha="center", va="center", transform=ax.transAxes)
    axes[0].set_ylabel("precision")
    save_figure(fig, path)


def write_figures(results: list[dict], folder) -> list[str]:
    """All figures for `results` into `folder`; returns their file names."""
    r0 = results[0]
    made = []
    where = "on the ground" if r0.get("distance", "ground") == "ground" else "in 3D"
    moda_figure(results, folder / "moda_ground.png", "moda_ground", f"match distance {where} (m)")
    made.append("moda_ground.png")
    pr_figure(results, folder / "pr_ground.png", "pr_ground", f"within {r0['pr_distance']} m")
    made.append("pr_ground.png")
    if any("moda_image" in r["penalise_hidden"] for r in results):
        moda_figure(results, folder / "moda_image.png", "moda_image", "box overlap (IoU) in the image")
        pr_figure(results, folder / "pr_image.png", "pr_image", f"IoU >= {r0['pr_overlap']}")
        made += ["moda_image.png", "pr_image.png"]
    if any("moda_cube" in r["penalise_hidden"] for r in results):
        moda_figure(results, folder / "moda_cube.png", "moda_cube", "3D box overlap (IoU)")
        pr_figure(results, folder / "pr_cube.png", "pr_cube", f"3D IoU >= {r0['pr_overlap']}")
        made += ["moda_cube.png", "pr_cube.png"]
    return made
