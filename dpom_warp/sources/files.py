"""A glob (or a folder) of depth frame files (16-bit PNG or .npy, in depth units), in sorted order."""

from __future__ import annotations

import glob
import os
from pathlib import Path
from typing import Iterator

import numpy as np

from ..io import InputError
from .base import Frame, Source, SourceInfo
from ..names import FRAME_SUFFIXES, unknown_format


class FileFrames(Source):
    """The files a glob matches, or a folder's .png and .npy files, in sorted order."""

    def __init__(self, pattern: str, key: str = "input.frames"):
        self.pattern, self.key = pattern, key
        folder = Path(os.path.expanduser(pattern))
        if folder.is_dir():  # a folder of frames: its frame files
            self.files = sorted(p for p in folder.iterdir() if p.is_file() and p.suffix.lower() in FRAME_SUFFIXES)
            if not self.files:
                raise InputError(f"{key}: {pattern}: a folder with no frames in it (expected 16-bit PNG or .npy "
                                 f"files; looked in {folder.resolve()})")
            return
        self.files = sorted(Path(p) for p in glob.glob(os.path.expanduser(pattern)) if Path(p).is_file())
        if not self.files:
            where = os.path.abspath(os.path.expanduser(pattern))
            raise InputError(f"{key}: no files match {pattern!r} (looked for {where}; relative paths in a "
                             f"config file are relative to its folder)")
        if len(self.files) == 1 and unknown_format(self.files[0]):
            raise InputError(f"{key}: {unknown_format(self.files[0])}")

    def _raw(self, f: Path) -> np.ndarray:
        from ..io import read_depth

        return read_depth(f, 1.0)  # the file's own units

    def info(self) -> SourceInfo:
        """Every file read once: `frames` counts those a run reads (the size of the first
        readable one, with some depth); `unreadable` says why each other one is not."""
        shape, readable, unreadable = None, [], []
        for f in self.files:
            try:
                raw = self._raw(f)
                if shape is not None and raw.shape != shape:
                    raise InputError(f"{f}: expected {shape[1]}x{shape[0]} pixels (the size of {readable[0].name}), "
                                     f"found {raw.shape[1]}x{raw.shape[0]}")
                if not np.any(raw > 0):
                    raise InputError(f"{f}: no depth readings (every pixel is 0)")
            except InputError as e:
                unreadable.append({"file": f.name, "reason": str(e)})
                continue
            shape = shape or raw.shape
            readable.append(f)
        if not readable:
            raise InputError(f"{self.pattern}: none of the {len(self.files)} files is a readable depth frame "
                             f"({unreadable[0]['reason']})")
        return SourceInfo(kind="depth frame files", path=self.pattern, frames=len(readable),
                          width=int(shape[1]), height=int(shape[0]),
                          encoding="16-bit PNG" if readable[0].suffix.lower() != ".npy" else ".npy",
                          streams=[{"topic": self.pattern, "type": "files", "messages": len(self.files)}],
                          unreadable=unreadable)

    def frames(self) -> Iterator[Frame]:
        for i, f in enumerate(self.files):
            try:
                yield Frame(i, None, self._raw(f))
            except InputError as e:
                yield Frame(i, None, None, str(e))
