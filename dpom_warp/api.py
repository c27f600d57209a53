"""The Python API: a Detector built from a run config, exactly as `dpom-warp run` builds it.

    from dpom_warp import Detector

    det = Detector.from_config("configs/demo_people.yaml")
    result = det.detect(depth)              # (H, W) at the camera's full resolution
    for d in result.detections:
        print(d.x, d.y, d.rho, d.box)
    tracks, report = det.track(det.detect_batch(frames))   # identities over a sequence
    online = det.online_tracker()           # or as frames come (a camera): what a live run does

    rig = Detector.from_config("rig.yaml")  # a config with cameras: [{name, input, camera}, ...]
    result = rig.detect([depth_0, depth_1])  # one frame a camera, in the config's order (or by name)

The Detector is the CLI's engine side: the same setup (`pipeline.set_up`: pose fit, background,
stride, sparse iterations, every default) and the same frame-to-detections step
(`worker.FrameWorker`), so it gives the detections of detections.csv at the run's speed. The
Engine (`dpom_warp.engine`) stays the low-level layer.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field
from pathlib import Path
from typing import Mapping

import numpy as np

from .config import ConfigError, RunConfig, apply_overrides, read_config
from .loading import config_from_mapping
from .detect import Detected
from .io import PLAUSIBLE_MEDIAN_M, InputError, array_to_metres, depth_scale_hint, implausible_median


@dataclass
class Result:
    """One frame's result.

    Attributes:
        detections: strongest first; each has `x`, `y`, `z` (world metres: z = 0 on a ground
            grid, the voxel centre's height in voxel mode), `rho` (rho*) and `box` (u0, v0,
            u1, v1: the silhouette's pixels at full resolution, inclusive).
        rho_star: the soft-thresholded occupancy map, grid-shaped: (ny, nx), or (nz, ny, nx).
        rho: the mean-field occupancy before the soft threshold, grid-shaped.
        iterations: mean-field iterations run.
        converged: False when the frame stopped at model.max_iterations above the tolerance.
        heads: each detection's head position (x, y), world metres, in the detections' order
            (None where no camera sees its head), or None where the config places none
            (tracking.positions; heads.py): where `track` puts the tracks.
        timings: seconds: the engine's stages (`lists_s`, `iterations_s`, `threshold_s` and
            within it `joint_lists_s`; a list a camera of the engine's: `lists_s_cameras`, and
            `iterations_s_cameras`, each camera's launches in the loop, None on a GPU), `infer_s`
            (this frame's share of its engine call), `detect_s` and `total_s`.
    """

    detections: list[Detected]
    rho_star: np.ndarray
    rho: np.ndarray
    iterations: int
    converged: bool
    timings: dict = field(default_factory=dict)
    heads: list | None = None

    def found(self) -> list:
        """The detections as heads.placed_rows takes them: [(x, y, head or None)]."""
        return [(d.x, d.y, h) for d, h in zip(self.detections, self.heads or [None] * len(self.detections))]


class Detector:
    """People (or drones) in depth frames, built once from a run config.

    Build it with `Detector.from_config`; `detect` takes one frame, `detect_batch` several
    (through `engine.batch` frames per engine call). Frames follow the config's camera:
    an integer array is in its depth units (input.depth_scale metres each; 0 = no reading),
    a float array in metres (0, NaN and inf = no reading). Errors and warnings number the
    frames in the order this Detector was given them, from 0 (`frames_given` counts them).
    """

    def __init__(self, cfg: RunConfig, setup):
        from .worker import FrameWorker

        self.config = cfg
        self.setup = setup
        self.worker = FrameWorker(setup.spec, engine=setup.engine)
        self.engine = self.worker.engine
        self.frames_given = 0  # frames passed to detect / detect_batch: errors and warnings number them so
        self._units_wrong: set[str] = set()  # the cameras whose last frame with readings had a median no depth camera gives

    @classmethod
    def from_config(cls, config: str | Path | Mapping, overrides: list[str] | Mapping | None = None,
                    device: str | None = None, log=None, first_frames=None) -> "Detector":
        """A Detector from a config file (relative paths in it are relative to its folder) or
        a mapping of the same form (relative paths relative to the current folder).

        Args:
            config: path of a YAML run config, or a mapping.
            overrides: `key.path=value` strings as for `--set`, or a mapping
                {"model.prior": 0.02, ...}.
            device: overrides the config's device ("cpu", "cuda:0", "auto").
            log: called with each setup line (the floor fit, the background); default: silent.
            first_frames: a live camera's first frames, as `detect` takes them, which a live run
                takes before inferring any: with extrinsics auto and no background frames the
                floor is fitted on the first camera.ground.frames of them, and floor-only the
                static planes are found in the first input.structure.frames (find_static_planes).

        Raises:
            ConfigError, InputError: one line naming the key or file.
        """
        from .frames import render_synthetic
        from .names import is_live
        from .session import set_up
        from .sources import expand

        if isinstance(config, Mapping):
            raw, where = dict(config), "config"
        else:
            raw, where = read_config(config), str(config)
        if isinstance(overrides, Mapping):
            overrides = [f"{k}={_yaml(v)}" for k, v in overrides.items()]
        try:
            cfg = config_from_mapping(apply_overrides(raw, list(overrides or [])))
        except ConfigError as e:
            raise ConfigError(f"{where}: {e}") from None
        quiet = log or (lambda *_: None)
        render_synthetic(cfg, quiet)
        # the run's frames where setting up reads them: auto, and without background frames the
        # floor fit (extrinsics: auto) and the static planes (input.structure) are found in them;
        # a live camera has none before (its frames are the ones given to detect)
        needs = [not is_live(m.inputs.frames) and (m.inputs.auto_background or (
            not m.inputs.background and (m.pose_auto or m.inputs.structure.planes))) for _, m in cfg.members()]
        if cfg.is_rig:  # the cameras' frames, paired, where one needs them (auto, or a floor fit on them)
            from .frames import rig_frames

            frames = rig_frames(cfg, log=quiet, check=False).frames if any(needs) else []
        else:
            frames = expand(cfg.inputs.frames, "input.frames", cfg.inputs.topic, quiet) if needs[0] and cfg.inputs.frames else []
        if first_frames is not None:
            return cls.from_first_frames(cfg, first_frames, device, quiet)
        return cls(cfg, set_up(cfg, frames, device, quiet))

    @classmethod
    def from_first_frames(cls, cfg: RunConfig, depths, device, log) -> "Detector":
        """from_config's `first_frames`: a live camera's Detector set up as a live run sets it up
        on the frames it takes first (the floor fit and the static planes), none inferred."""
        from .names import is_live
        from .session import add_static_planes, planes_from_frames, set_up_on_first_frames

        if cfg.is_rig or not is_live(cfg.inputs.frames):
            raise ConfigError(f"first_frames: expected a live camera's config (input.frames: realsense[:SERIAL]), "
                              f"found {'a rig' if cfg.is_rig else f'input.frames: {cfg.inputs.frames}'}, whose "
                              f"frames the Detector reads itself")
        frames = [checked_metres(d, i, cfg, "first_frames, ") for i, d in enumerate(depths)]
        if not frames:
            raise InputError("first_frames: expected at least one frame, found none")
        cfg, setup = set_up_on_first_frames(cfg, frames, "first_frames (the first {n})", device=device, log=log)
        if planes_from_frames(cfg):
            add_static_planes(setup, frames[:cfg.inputs.structure.frames], log)
        return cls(cfg, setup)

    @property
    def camera(self):
        """The posed camera (with extrinsics: auto, the fitted pose); a rig's: a list, one a camera."""
        return self.setup.spec.camera

    @property
    def ground_fit(self) -> dict | None:
        """With extrinsics: auto, the floor fit as summary.json's ground_fit holds it (camera
        height, pitch, roll, inliers, `floor_xy`: where the floor lies in view); else None."""
        return self.setup.ground

    @property
    def grid(self):
        return self.config.grid

    @property
    def device(self) -> str:
        return self.setup.device

    def detect(self, depth) -> Result:
        """Detections and maps of one (H, W) frame at the camera's full resolution; a rig's:
        one such frame a camera, a list in the config's camera order or a dict by name (a
        camera with no frame: None, inferred from the others)."""
        if self.config.is_rig:
            return self.detect_batch([depth])[0]
        return self.detect_batch(np.asarray(depth)[None])[0]

    def detect_batch(self, depths) -> list[Result]:
        """One Result per frame of `depths` ((n, H, W) or a sequence of (H, W) arrays; a rig's:
        a sequence of what `detect` takes), in order, each what `detect` gives it alone
        (engine.batch frames per engine call)."""
        from .engine import ListOverflow
        from .worker import stacked

        first = self.frames_given
        if self.config.is_rig:
            frames = [self._rig_metres(d, first + i) for i, d in enumerate(depths)]
        else:
            frames = [self._metres(d, first + i) for i, d in enumerate(depths)]
        self.frames_given += len(frames)
        engine, n = self.engine, self.engine.batch
        results = []
        for start in range(0, len(frames), n):
            part = frames[start:start + n]
            whole = not self.config.is_rig or all(d is not None for f in part for d in f)
            t0 = time.perf_counter()
            try:  # reduced by the engine (on a GPU there); a rig's frame missing a camera's alone
                out = (engine.infer_batch(stacked(part, self.config.is_rig)) if whole
                       else [self.worker.infer(f) for f in part])
            except ListOverflow as e:
                raise InputError(f"depth (frame {first + start}): {e}") from None
            share = (time.perf_counter() - t0) / len(part)
            for res, frame in zip(out, part):
                t1 = time.perf_counter()
                rho_map, dets = self.worker.detections(res)
                found = self.worker.heads(dets, frame, res)
                t2 = time.perf_counter()
                timings = {**res.timings, "infer_s": share, "detect_s": t2 - t1,
                           "total_s": share + t2 - t1}
                results.append(Result(dets, rho_map, res.rho.reshape(self.config.grid.shape),
                                      res.iterations, res.converged, timings, found))
        return results

    def track(self, results: list[Result], method: str | None = None, times: list | None = None):
        """Tracks over consecutive frames' results, as `dpom-warp run` writes them to tracks.csv
        (the config's tracking.* and input.fps; `method`: ksp or online instead of the
        config's; `times`: each result's frame timestamp in seconds, as a recording gives
        them: the rate is then the timestamps' and frames dropped between two results count,
        as in a run of the recording). Returns (tracks, report): each track has `id`, `frames`
        (indices into `results`), `xyz` (metres), `rho` and `bridged` (frames without a map
        peak)."""
        from .heads import Placer
        from .outputs import fps_of
        from .tracking import Cells, run_tracker

        cfg, geometry = self.config, self.worker.geometry
        cells = Cells.for_run(geometry, cfg)
        maps = np.stack([np.asarray(r.rho_star, np.float32).ravel() for r in results])
        if times is not None and len(times) != len(results):
            raise ValueError(f"times: expected one timestamp per result ({len(results)}), found {len(times)}")
        fps = (fps_of(list(times)) if times is not None else None) or cfg.inputs.fps
        tracks, report = run_tracker(maps, cells, cfg.grid.shape, cfg.tracking, fps, cfg.detection.threshold, method,
                                     None if times is None else list(times))
        placer = Placer.of(cfg)
        if placer is not None:  # at the detections' heads, as the run's tracks.csv
            placer.tracks(tracks, [r.found() for r in results])
        return tracks, report

    def online_tracker(self, fps: float | None = None) -> "OnlineTracks":
        """Identities as frames come, as a live run gives them: `push` each frame's Result
        (with its timestamp, where frames may be dropped between) and get back the frames the
        tracker has committed, tracking.delay frames behind, with their final identities;
        `finish` commits the rest. `fps`: the camera's rate (default input.fps). The tracks
        are those of `track(results, method="online", times=...)` at that rate."""
        from .tracking import Cells, OnlineTracker

        cfg = self.config
        rate = fps or cfg.inputs.fps
        tracker = OnlineTracker(Cells.for_run(self.worker.geometry, cfg), cfg.grid.shape, cfg.tracking, 1.0 / rate,
                                cfg.detection.threshold)
        return OnlineTracks(tracker, cfg)

    def find_static_planes(self, depths) -> dict:
        """Walls and furniture (input.structure's planes) found in `depths`, a camera's first
        frames as `detect` takes them, and made background for the frames that follow, as a
        live run finds them in its camera's first frames (a config whose input.frames the
        Detector read has them already). Floor-only, or `auto`'s floor-only pixels. Returns
        summary.json's inference.structure report (the planes, the pixels made background).

        A rig's `depths` are rig frames as `detect` takes them (a list in camera order or a dict
        by name, None where a camera has none): each floor-only camera's planes in its frames, the
        report by camera name.

        Raises:
            ConfigError: background frames (they explain the room; a rig: every camera's), or
                input.structure.planes false.
            InputError: a frame as `detect` refuses it, or no frame.
        """
        from .session import add_static_planes, planes_from_frames

        cfg = self.config
        if cfg.is_rig:
            if not any(planes_from_frames(m) for _, m in cfg.cameras):
                raise ConfigError("cameras: expected a camera with input.background null and input.structure.planes "
                                  "true for find_static_planes, found none (background frames explain the room)")
            frames = [self._rig_metres(d, i) for i, d in enumerate(depths)]
        else:
            if cfg.inputs.background and not cfg.inputs.auto_background:
                raise ConfigError(f"input.background: expected null or auto for find_static_planes, found background "
                                  f"frames ({cfg.inputs.background}), which explain the room already")
            if not cfg.inputs.structure.planes:
                raise ConfigError("input.structure.planes: expected true for find_static_planes, found false")
            frames = [self._metres(d, i, who="find_static_planes, ") for i, d in enumerate(depths)]
        if not frames:
            raise InputError("find_static_planes: expected at least one frame, found none")
        return add_static_planes(self.setup, frames, log=lambda *_: None)

    def _rig_metres(self, depths, index: int) -> list[np.ndarray]:
        """A rig's frame, a list in camera order or a dict by name, as metres a camera (None: that
        camera has no frame: the frame is inferred from the others, FrameWorker.infer)."""
        names = self.config.camera_names
        if isinstance(depths, Mapping):
            unknown = sorted(set(depths) - set(names))
            if unknown:
                raise InputError(f"depth (frame {index}): expected the rig's cameras {names}, found {unknown[0]!r}")
            depths = [depths.get(n) for n in names]
        elif isinstance(depths, np.ndarray) or not hasattr(depths, "__len__") or len(depths) != len(names):
            found = f"an array of shape {np.shape(depths)}" if isinstance(depths, np.ndarray) else (
                f"{len(depths)} entries" if hasattr(depths, "__len__") else type(depths).__name__)
            raise InputError(f"depth (frame {index}): expected a list of {len(names)} frames, one a camera of the rig "
                             f"({', '.join(names)}), or a dict by name; found {found}")
        out = []
        for (name, m), d in zip(self.config.cameras, depths):
            out.append(None if d is None else self._metres(d, index, m, f"camera {name}, "))
        return out

    def _metres(self, depth, index: int, cfg: RunConfig | None = None, who: str = "") -> np.ndarray:
        cfg = cfg or self.config
        metres = checked_metres(depth, index, cfg, who)
        self._check_units(metres, np.asarray(depth).dtype, index, cfg, who)
        return metres

    def _check_units(self, metres: np.ndarray, dtype, index: int, cfg: RunConfig | None = None, who: str = "") -> None:
        """Every frame's units, from the median of every 4th pixel of every 4th row (about
        0.2 ms at 512x424): a warning naming the frame when its median is one no depth camera
        gives (as `dpom-warp run` warns), the first such frame and again at the first after
        frames that were right. A frame in millimetres passed as floats, or integer units at
        the wrong input.depth_scale, leaves every reading out of the grid's reach and nothing is
        found, without a word of why. A rig's cameras (`who`, "camera NAME, ") each on their own."""
        sample = metres[::4, ::4]
        if not np.any(sample > 0):
            return
        if np.issubdtype(dtype, np.integer):
            hint = depth_scale_hint(sample, (cfg or self.config).inputs.depth_scale)
        else:
            median, (low, high) = implausible_median(sample), PLAUSIBLE_MEDIAN_M
            hint = None if median is None else (
                f"a float array is read as metres, and its readings' median is {median:.4g} m: expected "
                f"{low:g} to {high:g} m; pass metres, or the sensor's integer units (input.depth_scale)")
        if hint and who not in self._units_wrong:
            warnings.warn(f"depth ({who}frame {index}): {hint}", UserWarning, stacklevel=4)
        (self._units_wrong.add if hint else self._units_wrong.discard)(who)


class OnlineTracks:
    """Detector.online_tracker's tracker. Each committed frame comes as (index, tracks):
    `index` counts the frames pushed from 0, `tracks` is [(id, xyz, bridged)] by id (world
    metres; `bridged`: held without a map peak), the identities tracks.csv would hold."""

    def __init__(self, tracker, cfg: RunConfig):
        from .heads import Placer

        self._tracker = tracker
        self.tracks: list | None = None  # after finish: every track (id, frames, xyz, rho, bridged)
        self.report: dict | None = None  # after finish: solves, graph sizes, delay
        self._placer = Placer.of(cfg)  # each frame's detections and heads (None: tracks at the cells)

    def _placed(self, committed: list) -> list:
        if self._placer is None:
            return committed
        return [(f, self._placer.rows(f, rows)) for f, rows in committed]

    def push(self, result: Result, timestamp: float | None = None) -> list[tuple[int, list]]:
        """The next frame's result (`timestamp`: seconds, its camera's clock); returns the
        frames committed now (none until tracking.delay frames have come, then one a frame)."""
        if self.tracks is not None:
            raise RuntimeError("OnlineTracks.push after finish: expected a new online_tracker()")
        self._tracker.push(result.rho_star, timestamp)
        if self._placer is not None:
            self._placer.add(result.found())
        return self._placed(self._tracker.take_committed())

    def finish(self) -> list[tuple[int, list]]:
        """Commit the frames still waiting and return them; `tracks` then holds every track."""
        if self.tracks is None:
            self.tracks, self.report = self._tracker.finish()
            if self._placer is not None:
                self._placer.tracks(self.tracks)
        return self._placed(self._tracker.take_committed())


def checked_metres(depth, index: int, cfg: RunConfig, who: str = "") -> np.ndarray:
    """A frame as `detect` takes it, in metres: its shape the camera's, integers (the config's
    depth units) or floats (metres), nothing negative; else an InputError naming the frame."""
    depth = np.asarray(depth)
    shape = (cfg.camera.height, cfg.camera.width)
    if depth.shape != shape:
        raise InputError(f"depth ({who}frame {index}): expected an array of shape {shape} (camera.height, "
                         f"camera.width), found {depth.shape}")
    integer = np.issubdtype(depth.dtype, np.integer)
    if not integer and not np.issubdtype(depth.dtype, np.floating):
        raise InputError(f"depth ({who}frame {index}): expected an integer or float array, found {depth.dtype}")
    if integer and depth.min(initial=0) < 0:
        raise InputError(f"depth ({who}frame {index}): expected depth units >= 0, found {depth.min()}")
    metres = array_to_metres(depth, cfg.inputs.depth_scale)  # integers as read_depth reads them
    if metres.min(initial=0) < 0:
        raise InputError(f"depth ({who}frame {index}): expected metres >= 0, found {metres.min():g}")
    return metres


def _yaml(value) -> str:
    import json

    return json.dumps(value)  # JSON is YAML: the value parses back as given
