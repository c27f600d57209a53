"""What a written picture must hold, beyond existing: a PNG that decodes, at least the size it
is drawn at, and not blank (many colours, none covering nearly all of it; a plot's curves in
colour)."""

from pathlib import Path

import numpy as np
from PIL import Image


def hue(rgb: np.ndarray) -> np.ndarray:
    """Hue in degrees (0 to 359) of (N, 3) uint8 colours: an anti-aliased line keeps its hue
    where it fades into the white behind it."""
    c = rgb.astype(float) / 255
    mx, mn = c.max(1), c.min(1)
    d = np.where(mx > mn, mx - mn, 1.0)
    r, g, b = c.T
    h = np.where(mx == r, (g - b) / d % 6, np.where(mx == g, (b - r) / d + 2, (r - g) / d + 4))
    return (60 * h).astype(int) % 360


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
        drawn = int((np.bincount(hue(flat[coloured]) // 30, minlength=12) > 0.0005 * len(flat)).sum())
        assert drawn >= curves, f"{path}: curves in {drawn} colours, expected {curves}"
    return rgb
