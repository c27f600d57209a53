"""Frame-wide depth drift: a time-of-flight or stereo camera reads a whole frame a few percent
farther or nearer than the frame before (temperature, exposure, auto-calibration), which the
background model, fixed for the run, would take for objects everywhere. Each frame's depth
scale s (its readings over the background's depths) is estimated before inference on the
pixels that agree with the background (people and anything new lie in front of it and are left
out), and the frame divided by it.

The estimate, on a fixed sample of the background's pixels (those with a known depth: the
background frames' or auto's, or the floor plane's where the floor is seen): the ratios r =
z / mu_bg of the sample's readings within `max_scale` of 1; s0 their median; s the median of
those within `tolerance` of s0. It is trusted when at least `min_share` of the sample (and
MIN_PIXELS pixels) agree; an untrusted frame is inferred as read, and says so. A frame whose
scale is within `deadband` of 1 is also inferred as read (the model's own noise covers it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from pydantic import Field

from .values import Bool, Node, Num

SAMPLE = 4096  # background pixels the estimate reads (spread evenly over those with a known depth)
MIN_PIXELS = 50  # fewer agreeing pixels: not trusted, whatever their share


class DriftOptions(Node):  # the config's `input.drift` section
    """Each frame's depth scale estimated against the background and corrected before inference."""

    correct: Bool = Field(True, description="estimate each frame's depth scale against the background and "
                                            "divide the frame by it (false: frames as read)")
    max_scale: Num = Field(0.08, gt=0, lt=0.5, description="largest drift looked for: readings within this "
                                                           "share of the background's depth are candidates")
    tolerance: Num = Field(0.02, gt=0, lt=0.5, description="a pixel agrees within this share of the first "
                                                           "estimate")
    min_share: Num = Field(0.2, gt=0, le=1, description="share of the sampled background pixels that must agree "
                                                        "for the estimate to be trusted")
    deadband: Num = Field(0.005, ge=0, lt=0.5, description="a scale within this of 1 is left alone (the frame "
                                                           "inferred as read)")


@dataclass
class DriftEstimate:
    """One frame's drift: its depth `scale` against the background (1.0 when not `trusted`),
    the share of the sampled background pixels that agree with it, and whether the frame was
    divided by it (`applied`)."""

    scale: float
    agreeing: float
    trusted: bool
    applied: bool

    def record(self) -> dict:
        return {"scale": round(self.scale, 6), "agreeing": round(self.agreeing, 4), "trusted": self.trusted,
                "applied": self.applied}


def background_sample(mu: np.ndarray, known: np.ndarray, n: int = SAMPLE) -> np.ndarray:
    """Up to `n` pixel indices (flat) spread evenly over the pixels whose background depth is
    `known` (and positive)."""
    idx = np.flatnonzero(np.asarray(known).ravel() & (np.asarray(mu).ravel() > 0))
    if len(idx) > n:
        idx = idx[np.linspace(0, len(idx) - 1, n).round().astype(np.int64)]
    return idx


def estimate_scale(z: np.ndarray, mu: np.ndarray, options: DriftOptions) -> DriftEstimate:
    """The drift of one frame from its readings `z` at the sampled pixels (0: no reading) and
    the background's depths `mu` there (module doc)."""
    z, mu = np.asarray(z, np.float64), np.asarray(mu, np.float64)
    n = len(mu)
    ratio = np.divide(z, mu, out=np.zeros_like(z), where=(z > 0) & (mu > 0))
    near = ratio[np.abs(ratio - 1.0) <= options.max_scale]
    if len(near) == 0:
        return DriftEstimate(1.0, 0.0, False, False)
    first = float(np.median(near))
    agree = near[np.abs(near / first - 1.0) <= options.tolerance]
    share = len(agree) / max(n, 1)
    if len(agree) < MIN_PIXELS or share < options.min_share:
        return DriftEstimate(1.0, share, False, False)
    scale = float(np.median(agree))
    return DriftEstimate(scale, share, True, abs(scale - 1.0) > options.deadband)


def summary(estimates: dict) -> dict:
    """summary.json's `drift`: frames' scales by name ({name: record}): their range, the frames
    corrected and those whose estimate was not trusted."""
    if not estimates:
        return {}
    scales = np.array([e["scale"] for e in estimates.values() if e["trusted"]])
    return {"frames": len(estimates),
            "corrected": sum(e["applied"] for e in estimates.values()),
            "untrusted": [name for name, e in estimates.items() if not e["trusted"]],
            "scale_min": round(float(scales.min()), 6) if len(scales) else None,
            "scale_max": round(float(scales.max()), 6) if len(scales) else None,
            "scale_median": round(float(np.median(scales)), 6) if len(scales) else None}
