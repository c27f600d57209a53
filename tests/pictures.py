"""What a written picture must hold, beyond existing: a PNG that decodes, at least the size it
is drawn at, and not blank (many colours, none covering nearly all of it; a plot's curves in
colour)."""

from pathlib import Path

import numpy as np
from matplotlib.colors import rgb_to_hsv
from PIL import Image


def assert_picture(path: Path, min_size: tuple[int, int] = (100, 100), colours: int = 16,
                   plot: bool = False, curves: int = 1) -> np.ndarray:
    """Checks `path` and returns its pixels (H, W, 3). A `plot` (lines on white) must also show
    coloured pixels, its curves (axes and labels are grey), in at least `curves` colours."""
    with Image.open(path) as im:
        assert im.format == "PNG", f"{path}: {im.format}, not a PNG"
        rgb = np.asarray(im.convert("RGB"))
    h, w = rgb.shape[:2]
    assert w >= min_size[0] and h >= min_size[1], f"{path}: {w}x{h}, smaller than {min_size}"
    flat = rgb.reshape(-1, 3)
    values, counts = np.unique(flat, axis=0, return_counts=True)
    assert len(values) >= colours, f"{path}: {len(values)} colours: blank"
    assert counts.max() < 0.98 * len(flat), f"{path}: one colour covers {counts.max() / len(flat):.0%}: blank"
    if plot:
        coloured = (flat.max(1).astype(int) - flat.min(1)) > 60
        assert coloured.mean() > 0.002, f"{path}: {coloured.mean():.2%} coloured pixels: no curve drawn"
        # hue, which an anti-aliased line keeps where it fades into the white behind it, in 30 deg bins
        hue = rgb_to_hsv(flat[coloured] / 255.0)[:, 0]
        drawn = int((np.bincount((hue * 12).astype(int) % 12, minlength=12) > 0.0005 * len(flat)).sum())
        assert drawn >= curves, f"{path}: curves in {drawn} colours, expected {curves}"
    return rgb
