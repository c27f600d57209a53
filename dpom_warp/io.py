"""Depth frames in and results out. Every output file is written atomically
(temporary file in the same folder, then rename), so a crash never leaves half a file."""

from __future__ import annotations

import io
import json
import os
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np
from PIL import Image


class InputError(ValueError):
    """Bad input file or value; the message is one line naming the file."""


class WorkerError(RuntimeError):
    """A worker process of `run --workers` died (killed, out of memory); one line says so."""


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


_FILE_MODE = 0o666 & ~_umask()
TEMP_MARK = ".tmp-"  # in the name of every temporary file, so a killed run's leftovers are found


@contextmanager
def atomic_path(path: str | Path, suffix: str = ""):
    """Yield a temporary path beside `path`; on success it is renamed onto `path`."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = None
    try:  # (Ctrl-C inside mkstemp itself can still leave one: the runs remove those, remove_temporaries)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}{TEMP_MARK}", suffix=suffix or path.suffix,
                                   dir=path.parent)
        os.close(fd)
        yield Path(tmp)
        os.chmod(tmp, _FILE_MODE)  # mkstemp makes 0600 files; outputs are ordinary files
        os.replace(tmp, path)
    except BaseException:
        if tmp is not None:
            Path(tmp).unlink(missing_ok=True)
        raise


def write_json_atomic(path, obj):
    with atomic_path(path) as tmp:
        tmp.write_text(json.dumps(obj, indent=2) + "\n")


def write_npy_atomic(path, array):
    with atomic_path(path) as tmp:
        with open(tmp, "wb") as f:
            np.save(f, array)


def write_text_atomic(path, text: str):
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_bytes_atomic(path, data: bytes):
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_depth_png(path, depth_m: np.ndarray, depth_scale: float = 0.001):
    """Save depth in metres as a 16-bit PNG in units of `depth_scale` (0 = no reading)."""
    units = np.clip(np.round(np.asarray(depth_m) / depth_scale), 0, 65535).astype(np.uint16)
    with atomic_path(path) as tmp:
        Image.fromarray(units).save(tmp, format="PNG")


NPY_MAGIC = b"\x93NUMPY"


def _is_npy(path: Path, data: bytes | None) -> bool:
    """A file without a telling suffix (a recording's cached frames) that holds an array."""
    if data is not None:
        return data[:6] == NPY_MAGIC
    with open(path, "rb") as f:
        return f.read(6) == NPY_MAGIC


def units_to_metres(raw: np.ndarray, depth_scale: float) -> np.ndarray:
    """Depth in the sensor's units (0 = no reading) as float32 metres, the one conversion every
    reader uses (files, the Python API, live cameras), so that they give the same bits."""
    return (np.asarray(raw).astype(np.float64) * depth_scale).astype(np.float32)


def array_to_metres(depth: np.ndarray, depth_scale: float) -> np.ndarray:
    """A depth array as float32 metres: integers are the sensor's units (units_to_metres),
    floats metres already (NaN and inf: no reading, 0)."""
    if np.issubdtype(depth.dtype, np.integer):
        return units_to_metres(depth, depth_scale)
    return np.where(np.isfinite(depth), depth, 0).astype(np.float32)


PLAUSIBLE_MEDIAN_M = (0.15, 30.0)  # a depth camera's readings' median lies in here, metres


def implausible_median(depth_m: np.ndarray) -> float | None:
    """The median of a frame's readings (metres; 0, NaN: none) where no depth camera gives it
    (outside PLAUSIBLE_MEDIAN_M), else None (None too without readings)."""
    d = np.asarray(depth_m)
    valid = d[np.isfinite(d) & (d > 0)]
    if not valid.size:
        return None
    median = float(np.median(valid))
    return None if PLAUSIBLE_MEDIAN_M[0] <= median <= PLAUSIBLE_MEDIAN_M[1] else median


def depth_scale_hint(depth_m: np.ndarray, depth_scale: float) -> str | None:
    """A word about input.depth_scale when a frame's readings have a median no depth camera
    gives (implausible_median), else None: a scale off by 1000 leaves every reading beyond
    the grid, or in front of the camera's lens, and nothing is found."""
    median = implausible_median(depth_m)
    if median is None:
        return None
    return (f"its readings' median is {median:.4g} m, at input.depth_scale {depth_scale:g} m per unit: "
            f"expected {PLAUSIBLE_MEDIAN_M[0]:g} to {PLAUSIBLE_MEDIAN_M[1]:g} m; is the scale right?")


def read_depth(path: str | Path, depth_scale: float, shape: tuple[int, int] | None = None,
               data: bytes | None = None) -> np.ndarray:
    """Read a depth frame (16-bit PNG in depth units, or .npy; a file named without a suffix is
    told by its content) as float32 metres, 0 = no reading.

    Args:
        path: the file.
        depth_scale: metres per unit of the file's values.
        shape: expected (height, width), checked when given.
        data: the file's bytes, read elsewhere (a cluster's actor gets them from the
            driver); `path` then only names the frame and its kind.

    Raises:
        InputError: missing or unreadable file, not a single-channel 16-bit depth image,
            non-finite or negative values, wrong size.
    """
    path = Path(path)
    if data is None and not path.is_file():
        raise InputError(f"{path}: no such file")
    source = path if data is None else io.BytesIO(data)
    if path.suffix.lower() == ".npy" or (path.suffix.lower() != ".png" and _is_npy(path, data)):
        try:
            raw = np.load(source, allow_pickle=False)
        except Exception as e:  # noqa: BLE001 - numpy raises many kinds
            raise InputError(f"{path}: not a readable .npy file ({e})") from None
        if raw.ndim != 2 or not np.issubdtype(raw.dtype, np.number):
            raise InputError(f"{path}: expected a 2-D numeric depth array, found shape {raw.shape} "
                             f"dtype {raw.dtype}")
        bad = int(np.count_nonzero(~np.isfinite(raw)))
        if bad:
            raise InputError(f"{path}: depth has NaN or infinite values: expected finite depth units "
                             f"(0 = no reading), found {bad} of {raw.size} pixels not finite")
        if np.any(raw < 0):
            raise InputError(f"{path}: depth has negative values: expected depth units >= 0 (0 = no "
                             f"reading), found a minimum of {raw.min():g}")
    else:
        try:
            with Image.open(source) as im:
                im.load()
                mode = im.mode
                raw = np.asarray(im)
        except Exception as e:  # noqa: BLE001 - PIL raises many kinds
            raise InputError(f"{path}: not a readable image ({type(e).__name__}: {e})") from None
        if raw.ndim != 2 or raw.dtype not in (np.uint16, np.int32, np.uint32):
            raise InputError(f"{path}: expected a single-channel 16-bit depth PNG, found mode {mode}")
    if shape is not None and raw.shape != tuple(shape):
        raise InputError(f"{path}: expected {shape[1]}x{shape[0]} pixels (camera.width x "
                         f"camera.height), found {raw.shape[1]}x{raw.shape[0]}")
    return units_to_metres(raw, depth_scale)
