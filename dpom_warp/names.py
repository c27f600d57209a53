"""What `input.frames` names, told from the name alone (no file is opened but a folder's
metadata.yaml looked for): a live camera (`realsense[:SERIAL]`), a recording (by its suffix,
or a ROS 2 bag's folder) or, otherwise, a glob of frame files. The config (which of its
values are paths) and the sources (which reader opens one) both ask."""

from __future__ import annotations

import os
from pathlib import Path

# every kind of source: what it is, and its reader (module in dpom_warp/sources/, class), imported
# when used (the readers of recordings and cameras need the optional [sensors] extra); live
# cameras by the name input.frames gives them (`NAME` or `NAME:SERIAL`), recordings by suffix.
# A new kind is its reader's file and one entry here.
READERS = {
    "realsense": ("a live RealSense camera", "realsense", "RealSenseLive"),
    "files": ("depth frame files", "files", "FileFrames"),
    ".bag": ("ROS 1 bag", "bags", "Bag"),
    ".db3": ("ROS 2 bag (sqlite)", "bags", "Bag"),
    ".mcap": ("ROS 2 bag (MCAP)", "bags", "Bag"),
    ".mkv": ("Azure Kinect recording", "azure", "AzureKinect"),
}
FRAME_SUFFIXES = (".png", ".npy")  # frame files (16-bit PNG or .npy, in depth units)
RECORDING_SUFFIXES = {k: what for k, (what, _, _) in READERS.items() if k.startswith(".")}
LIVE_KINDS = tuple(k for k in READERS if not k.startswith(".") and k != "files")


def live_kind(spec) -> str | None:
    """The kind of live camera input.frames names (`NAME` or `NAME:SERIAL`), else None."""
    name = str(spec).split(":", 1)[0]
    return name if name in LIVE_KINDS else None


def is_live(spec) -> bool:
    """Whether input.frames names a live camera."""
    return live_kind(spec) is not None


def is_recording(spec: str | os.PathLike) -> bool:
    """Whether input.frames names a recording (by its suffix, or a ROS 2 bag's folder)."""
    p = Path(os.path.expanduser(str(spec)))
    return p.suffix.lower() in RECORDING_SUFFIXES or (p.is_dir() and (p / "metadata.yaml").is_file())


def unknown_format(spec) -> str | None:
    """Where input.frames names one file (no glob, not a folder, not a camera) of a kind no
    reader takes: the one-line reason, naming the file and the formats known; else None."""
    text = os.path.expanduser(str(spec))
    p = Path(text)
    if is_live(spec) or any(c in text for c in "*?[") or p.is_dir() or not p.suffix:
        return None
    if p.suffix.lower() in FRAME_SUFFIXES or p.suffix.lower() in RECORDING_SUFFIXES:
        return None
    return (f"{spec}: unknown format {p.suffix!r}; expected a folder or glob of 16-bit PNG or .npy frames, "
            f"a recording ({', '.join(RECORDING_SUFFIXES)}, a ROS 2 bag's folder) or a live camera "
            f"({', '.join(f'{k}[:SERIAL]' for k in LIVE_KINDS)})")
