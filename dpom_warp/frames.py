"""The run's frames, from one place: the synthetic renderer (a config's `synthetic` section
renders its sequence first), a glob of frame files, or a recording read into its cache; each
frame checked once before anything is written. `run_frames` is what the plan reads: the good
frames in order, the skipped ones with reasons, a recording's timestamps and the notes where
the config's camera differs from the recording's.

A rig's frames (issue 61): each camera's frames found and checked as a single camera's are,
then paired with the first camera's, which names and times the rig's frames. Folders of frames
pair by their place in sorted order; recordings by timestamp, each first-camera frame with the
camera's nearest frame within `rig.tolerance` seconds (default half the first camera's frame
period). A rig frame where a camera has no frame (its frames ran out, a bad file, nothing near
enough in time) is inferred from the cameras that have one: its record says which."""

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
    if cfg.is_rig:  # each camera's frames, paired with the first camera's
        return rig_frames(cfg, strict, log, max_frames)
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
    if cfg.is_rig:  # one scene seen by every camera: NAME/frames, NAME/background
        from .synthetic_rig import generate_rig

        generate_rig(cfg.synthetic, [(n, m.camera) for n, m in cfg.cameras], cfg.synthetic_cache)
    else:
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
    if not cfg.is_rig:
        return PlayedFrames(got.frames, cfg.camera.width, cfg.camera.height, cfg.inputs.fps, stamps,
                            str(cfg.inputs.frames)), got.frames
    # a rig's: each camera plays its frames of the paired rig frames at their rig frame's time
    # (the first camera's timestamp, else the frame's place at input.fps), all from one start,
    # so that RigStream pairs them as they were paired here
    from .sources.rig import RigStream

    times = stamps or [i / cfg.inputs.fps for i in range(len(got.frames))]
    cameras = []
    for c, (name, m) in enumerate(cfg.cameras):
        mine = [(f.paths[c], t) for f, t in zip(got.frames, times) if f.paths[c] is not None]
        cameras.append(PlayedFrames([p for p, _ in mine], m.camera.width, m.camera.height, cfg.inputs.fps,
                                    [t for _, t in mine], str(m.inputs.frames), start_at=times[0] if times else 0.0))
    return RigStream(cameras, cfg.camera_names, cfg.rig.tolerance), got.frames


# -- a rig's frames ------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class RigFrame:
    """One frame of a rig: a file (or None) a camera, the first camera's always there; named as
    the first camera's file (outputs, records, ground truth)."""

    paths: tuple

    @property
    def name(self) -> str:
        return self.paths[0].name

    @property
    def stem(self) -> str:
        return self.paths[0].stem

    def __str__(self) -> str:
        return str(self.paths[0])


def pair_by_index(first: int, counts: list[int]) -> list[list[int | None]]:
    """For each of the first camera's `first` frames, each other camera's frame at the same
    place in its order (None where its `counts` frames have run out)."""
    return [[i if i < n else None for n in counts] for i in range(first)]


def pair_by_time(first: np.ndarray, others: list[np.ndarray], tolerance: float) -> list[list[int | None]]:
    """For each of the first camera's timestamps, each other camera's frame nearest in time
    when within `tolerance` seconds (at exactly the tolerance: paired), else None."""
    out = []
    for t in np.asarray(first, float):
        row = []
        for stamps in others:
            stamps = np.asarray(stamps, float)
            if not len(stamps):
                row.append(None)
                continue
            j = int(np.argmin(np.abs(stamps - t)))
            row.append(j if abs(stamps[j] - t) <= tolerance else None)
        out.append(row)
    return out


def default_tolerance(cfg: RunConfig, stamps: np.ndarray | None) -> float:
    """rig.tolerance, else half the first camera's frame period: its timestamps' median step,
    else 1 / input.fps."""
    if cfg.rig is not None and cfg.rig.tolerance is not None:
        return float(cfg.rig.tolerance)
    if stamps is not None and len(stamps) > 1:
        return float(np.median(np.diff(np.sort(stamps)))) / 2
    return 0.5 / cfg.inputs.fps


def camera_words(cfg: RunConfig, i: int) -> str:
    """'cameras[i] (NAME)', how messages name a rig's camera."""
    return f"cameras[{i}] ({cfg.cameras[i][0]})"


def rig_frames(cfg: RunConfig, strict: bool = False, log=print, max_frames: int | None = None, check: bool = True):
    """frames.RunFrames of a rig: its frames RigFrames in the first camera's order, each camera's
    frames checked (a bad one leaves its camera out of that rig frame; the first camera's skips
    the rig frame), the first camera's timestamps; a warning per camera that misses frames.
    `check` False: the frames paired, none read (what a finished run's `track` and the API need:
    the run, or the reader, meets a bad one)."""
    render_synthetic(cfg, log)
    listed, stamps, unread = [], [], []
    for i, (name, m) in enumerate(cfg.cameras):
        key = f"cameras[{i}].input.frames"
        if m.inputs.frames is None:
            raise ConfigError(f"{key}: required key is missing (the frames of camera {name})")
        files, meta = source_frames(m.inputs.frames, key, m.inputs.topic, log)
        if meta is not None:
            for note in recording_notes(m, meta):
                log(f"{camera_words(cfg, i)}: {note}")
        listed.append(files)
        stamps.append(np.array([f["timestamp"] for f in meta["frames"]]) if meta is not None else None)
        if i == 0 and meta is not None:  # the first camera's recording's unreadable messages: no rig frame
            unread = list(meta["skipped"])
    first = listed[0][:max_frames] if max_frames is not None else listed[0]
    if max_frames is not None and len(listed[0]) > max_frames:
        log(f"--max-frames: the first {max_frames} of {len(listed[0])} frames")
    timed = all(s is not None for s in stamps)
    if timed:
        tolerance = default_tolerance(cfg, stamps[0])
        pairs = pair_by_time(stamps[0][:len(first)], stamps[1:], tolerance)
    else:
        pairs = pair_by_index(len(first), [len(f) for f in listed[1:]])
    chosen = [[f] + [None if j is None else listed[c + 1][j] for c, j in enumerate(row)] for f, row in zip(first, pairs)]
    good, why = [], {}
    for c, (name, m) in enumerate(cfg.cameras):
        mine = [row[c] for row in chosen if row[c] is not None]
        if not mine:
            how = f"by timestamp within {tolerance:g} s; rig.tolerance" if timed else "by their order"
            raise InputError(f"cameras[{c}].input.frames: none of its {len(listed[c])} frames pairs with one of "
                             f"cameras[0]'s {len(first)} ({how})")
        try:
            ok, bad = (check_frames(mine, m.inputs.depth_scale, (m.camera.height, m.camera.width), strict) if check
                       else (mine, []))
        except (InputError, ConfigError) as e:
            raise type(e)(f"{camera_words(cfg, c)}: {e}") from None
        good.append(set(ok))
        for item in bad:
            log(f"{camera_words(cfg, c)}: skipping {item['reason']}")
            if c == 0:
                why[item["frame"]] = item["reason"]
    frames, skipped = [], list(unread)
    for row in chosen:
        if row[0] not in good[0]:  # the first camera's frame names and times the rig's: none, no rig frame
            skipped.append({"frame": row[0].name, "reason": f"{camera_words(cfg, 0)}: {why.get(row[0].name, row[0])}"})
            continue
        frames.append(RigFrame(tuple(p if p in good[c] else None for c, p in enumerate(row))))
    for c in range(1, len(cfg.cameras)):
        missing = [f.name for f in frames if f.paths[c] is None]
        if missing:
            log(f"warning: {camera_words(cfg, c)}: no frame for {len(missing)} of the rig's {len(frames)} frames "
                f"(first {missing[0]}): inferred from the other cameras")
    timestamps = {}
    if stamps[0] is not None:
        at = {Path(f).name: t for f, t in zip(listed[0], stamps[0])}
        timestamps = {f.name: float(at[f.name]) for f in frames}
    return RunFrames(frames, skipped, timestamps, None)
