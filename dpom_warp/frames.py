"""The run's frames, from one place: the synthetic renderer (a config's `synthetic` section
renders its sequence first), a glob of frame files, or a recording read into its cache; each
frame checked once before anything is written. `run_frames` is what the plan reads: the good
frames in order, the skipped ones with reasons, a recording's timestamps and the notes where
the config's camera differs from the recording's."""

from __future__ import annotations

import dataclasses
import time
from collections import Counter
from pathlib import Path

import numpy as np

from .config import ConfigError, RunConfig
from .io import InputError, read_depth
from .sources import source_frames
from .synthetic import generate


@dataclasses.dataclass
class RunFrames:
    """The frames a run infers: `frames` (files, in order), `skipped` ({frame, reason}),
    `timestamps` (frame name -> seconds, a recording's), `meta` (a recording's source.json)."""

    frames: list
    skipped: list
    timestamps: dict
    meta: dict | None = None


def run_frames(cfg: RunConfig, strict: bool = False, log=print, max_frames: int | None = None) -> RunFrames:
    """Render a synthetic scene if the config has one, then find, read and check input.frames
    (with `strict`, the first bad frame is fatal; `max_frames`: the first that many of them, in
    order, a recording's by its stream)."""
    render_synthetic(cfg, log)
    if cfg.inputs.frames is None:
        raise ConfigError("input.frames: required key is missing (the frames to run on)")
    files, meta = source_frames(cfg.inputs.frames, "input.frames", cfg.inputs.topic, log)
    if max_frames is not None and len(files) > max_frames:
        log(f"--max-frames: the first {max_frames} of {len(files)} frames")
        files = files[:max_frames]
    unread, timestamps = [], {}
    if meta is not None:
        for note in recording_notes(cfg, meta):
            log(note)
        unread = list(meta["skipped"])
        if unread and strict:
            raise InputError(unread[0]["reason"])
        timestamps = {f["frame"]: f["timestamp"] for f in meta["frames"]}
    frames, skipped = check_frames(files, cfg.inputs.depth_scale, (cfg.camera.height, cfg.camera.width), strict)
    skipped = unread + skipped
    for item in skipped:
        log(f"skipping {item['reason']}")
    return RunFrames(frames, skipped, timestamps, meta)


def render_synthetic(cfg: RunConfig, log=print) -> None:
    """A config with a `synthetic` section: render its sequence (once: later calls check it)."""
    if cfg.synthetic is None:
        return
    t = time.perf_counter()
    cached = (Path(cfg.synthetic_cache) / "scene.json").exists()
    if not cached:
        log(f"rendering the synthetic scene ({cfg.synthetic.frames} frames) into {cfg.synthetic_cache} ...")
    generate(cfg.synthetic, cfg.camera, cfg.synthetic_cache)
    log(f"synthetic scene: {cfg.synthetic.frames} frames in {cfg.synthetic_cache} "
        f"({'checked' if cached else 'generated'} in {time.perf_counter() - t:.1f} s)")


def recording_notes(cfg: RunConfig, meta: dict) -> list[str]:
    """Where the config's camera differs from the recording's (the config's is used)."""
    info, cam, notes = meta["info"], cfg.camera, []
    mine = {"width": cam.width, "height": cam.height}
    for key in ("width", "height"):
        if info.get(key) and info[key] != mine[key]:
            notes.append(f"camera.{key}: the config's {mine[key]} differs from the recording's {info[key]}")
    if info.get("intrinsics"):
        for k, v in info["intrinsics"].items():
            given = getattr(cam, k)
            if abs(given - v) > 1e-6 * max(1.0, abs(v)):
                notes.append(f"camera.intrinsics.{k}: the config's {given:g} differs from the recording's {v:g}")
    if abs(cfg.inputs.depth_scale - meta["depth_scale"]) > 1e-9 * meta["depth_scale"]:
        notes.append(f"input.depth_scale: the config's {cfg.inputs.depth_scale:g} differs from the "
                     f"recording's {meta['depth_scale']:g}")
    return [n + " (the config's is used)" for n in notes]


def check_frames(frames: list[Path], scale: float, shape, strict: bool) -> tuple[list[Path], list[dict]]:
    """Read every frame once before any output is written. Returns the good frames and the
    skipped ones with reasons; with `strict`, or when no frame is good, the first error."""
    good, skipped = [], []
    for f in frames:
        try:
            depth = read_depth(f, scale, shape)
            if not np.any(depth > 0):
                raise InputError(f"{f}: no depth readings (every pixel is 0)")
            good.append(f)
        except InputError as e:
            if strict:
                raise
            skipped.append({"frame": f.name, "reason": str(e)})
    if not good:
        raise InputError(skipped[0]["reason"] + (f" (none of the {len(frames)} frames is usable)"
                                                 if len(frames) > 1 else ""))
    dup = next((s for s, n in Counter(f.stem for f in good).items() if n > 1), None)
    if dup:
        raise ConfigError(f"input.frames: two frames share the name {dup!r} (outputs are named "
                          f"by it); expected distinct names")
    return good, skipped


def played_source(cfg: RunConfig, log, max_frames: int | None):
    """(PlayedFrames, the frames) of input.play: the frames a plain run reads (rendered,
    read from a recording, checked: a bad one skipped), at a recording's timestamps or at
    input.fps."""
    from .sources.played import PlayedFrames

    try:
        got = run_frames(cfg, False, log, max_frames)
    except (InputError, ConfigError) as e:
        raise type(e)(cfg.blame(str(e))) from None
    names = [f.name for f in got.frames]
    stamps = [got.timestamps[n] for n in names] if got.timestamps and all(n in got.timestamps for n in names) else None
    return PlayedFrames(got.frames, cfg.camera.width, cfg.camera.height, cfg.inputs.fps, stamps,
                        str(cfg.inputs.frames)), got.frames
