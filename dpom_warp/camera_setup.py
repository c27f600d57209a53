"""One camera of a run set up, before the engine: its background frames read, its pose fitted
on the floor (`camera.extrinsics: auto`; the recording's IMU its up) with the warnings a fit
that cannot be wrong quietly gives, its background set in its engine view (frames, `auto`, the
floor) and its static planes made background. session.set_up does this for a run's camera, and
for each camera of a rig."""

from __future__ import annotations

import dataclasses
import time
from pathlib import Path

import numpy as np

from .background import BackgroundEstimator, sample_frames
from .config import ConfigError, RunConfig
from .geometry import build_geometry
from .ground import fit_ground_files, fit_ground_named, frames_named, noise_b, noise_ratio, noise_words
from .io import InputError, depth_scale_hint
from .names import is_live
from .resolution import Resolution
from .sources import expand
from .worker import read_frame


def _ambiguity(fit, log) -> dict:
    """A floor fit's ambiguity (camera.ground.up: auto), logged and for summary.json's ground."""
    if not fit.ambiguity:
        return {}
    log(f"warning: {fit.ambiguity}")
    return {"ambiguity": fit.ambiguity}


def floor_words(floor_xy) -> str:
    """'floor in view x .. to .. m, y .. to .. m' of a floor fit's floor_xy (where the grid goes)."""
    x0, x1, y0, y1 = floor_xy
    return f"floor in view x {x0:g} to {x1:g} m, y {y0:g} to {y1:g} m"


# a fitted floor that puts the camera outside these is worth a word (a wall or a desk taken for
# the floor, or a grid placed beside the view): mounted depth cameras are level in roll within
# a few degrees, between knee and ceiling height, and look down or level
POSE_ROLL_DEG = 30.0


POSE_HEIGHT_M = (0.3, 6.0)


POSE_PITCH_DEG = -15.0


GRID_IN_VIEW = 0.5  # the share of the grid's locations at least partly in the image


def pose_warnings(report: dict, in_view: float, cells: int, floor_xy=None) -> list[str]:
    """What is implausible about a fitted floor (`report`: the fit's camera_height, pitch_deg and
    roll_deg) or the grid it leaves in view (`in_view`: the share of the grid's `cells` whose
    silhouette is at least partly in the image): one line each, naming what was found and the
    key that fixes it."""
    h, pitch, roll = report["camera_height"], report["pitch_deg"], report["roll_deg"]
    pose = f"camera {h:.2f} m above it, pitch {pitch:.1f} deg, roll {roll:.1f} deg"
    odd = []
    if abs(roll) > POSE_ROLL_DEG:
        odd.append(f"a roll of {roll:.1f} deg (mounted cameras are level within {POSE_ROLL_DEG:g})")
    if not POSE_HEIGHT_M[0] <= h <= POSE_HEIGHT_M[1]:
        odd.append(f"a camera {h:.2f} m above the floor (expected {POSE_HEIGHT_M[0]:g} to {POSE_HEIGHT_M[1]:g} m)")
    if pitch < POSE_PITCH_DEG:
        odd.append(f"a camera looking {-pitch:.1f} deg up")
    out = []
    if odd:
        out.append(f"camera.extrinsics: auto: the floor found ({pose}) means {' and '.join(odd)}; if the camera "
                   f"is not mounted so, the plane taken for the floor is a wall or a desk: give camera.extrinsics "
                   f"(or camera.ground.up)")
    if in_view < GRID_IN_VIEW:
        seen = f" ({floor_words(floor_xy)})" if floor_xy is not None else ""
        out.append(f"grid: with the floor found ({pose}) {100 * (1 - in_view):.0f} % of its {cells} locations are "
                   f"out of the camera's view{seen}; expected grid.x and grid.y over the floor in view, or "
                   f"camera.extrinsics if that plane is not the floor")
    return out


def posed(cfg: RunConfig, fit, fitted_on: str, frames, t0: float, log):
    """The camera posed by a floor fit and summary.json's ground_fit report, the fit logged
    ("ground plane from `fitted_on`: ..."); `frames`: what the report says it was fitted on.
    The floor's depth noise, where the fit has one, goes into the report (`depth_noise`), with
    a warning where the model's is far from it (noise_warning)."""
    floor = f"; {floor_words(fit.floor_xy)}" if fit.floor_xy is not None else ""
    log(f"ground plane from {fitted_on}: camera {fit.camera_height:.3f} m above the floor, pitch "
        f"{fit.pitch_deg:.2f} deg, roll {fit.roll_deg:.2f} deg ({fit.inlier_count} inliers, rms "
        f"{1000 * fit.rms_m:.1f} mm){floor}")
    report = {**fit.report(), "rms_m": fit.rms_m, "floor_xy": fit.floor_xy, "frames": frames,
              "fit_s": time.perf_counter() - t0, **_ambiguity(fit, log)}
    if fit.noise is not None:
        report["depth_noise"] = fit.noise
        warned = noise_warning(fit.noise, cfg.model.sensor_noise)
        if warned:
            log(f"warning: {warned}")
            report["noise_warning"] = warned
    return dataclasses.replace(cfg.camera, T_world_from_camera=fit.T_world_from_camera), report


NOISE_OFF = 1.3  # the floor's noise this many times the model's, or the model's the floor's: a warning


def noise_warning(noise: dict, model_noise) -> str | None:
    """One line when the floor's depth noise (ground.floor_noise) is NOISE_OFF times
    model.sensor_noise's sigma or more, or 1 / NOISE_OFF or less (over its bins, weighted by
    their readings), naming the key and the (a, b) the floor shows (with the model's a); else None."""
    a, b = model_noise
    ratio = noise_ratio(noise["bins"], a, b)
    if 1.0 / NOISE_OFF < ratio < NOISE_OFF:
        return None
    own = noise_b(noise["bins"], a)
    return (f"model.sensor_noise: the floor's depth readings scatter {ratio:.1f}x what [{a:g}, {b:g}] says "
            f"({noise_words(noise)}); this sensor's is about [{a:g}, {own:g}] (sigma(z) = a + b z^2, "
            f"metres): set model.sensor_noise to it")


def fit_camera_pose(cfg: RunConfig, files: list[Path], log=print):
    """camera.extrinsics: auto. Fit the floor on `files` (input.background's, else
    input.frames') and return the posed camera and a report for summary.json.

    Raises:
        InputError: naming the frames (a recording's by the recording and frame), when no
            floor plane is found in them.
    """
    from .names import is_recording

    t = time.perf_counter()
    kind = "background frame" if cfg.inputs.background else "frame"
    log(f"fitting the floor on {len(files)} {kind}{'s' if len(files) > 1 else ''} ...")
    source = cfg.inputs.background or cfg.inputs.frames
    names = [f"{source} (frame {f.name})" for f in files] if source and is_recording(source) else None
    fit = fit_ground_files(files, cfg.camera, cfg.inputs.depth_scale, cfg.ground, names)
    refuse_low_view_from_above(cfg, fit, frames_named(files, names))
    return posed(cfg, fit, f"{len(files)} {kind}{'s' if len(files) > 1 else ''}", names or [str(f) for f in files],
                 t, log)  # a recording's frames by the recording and frame, not the cache's files


def fit_pose_on_frames(cfg: RunConfig, frames_m: list, named: str, log=print):
    """camera.extrinsics: auto on frames in hand (metres, full resolution: a live camera's first,
    `named` in messages): the posed camera and summary.json's ground_fit report, as
    fit_camera_pose gives them for files."""
    t = time.perf_counter()
    log(f"fitting the floor on {named} ...")
    fit = fit_ground_named(frames_m, cfg.camera, cfg.ground, named, cfg.inputs.depth_scale)
    refuse_low_view_from_above(cfg, fit, named)
    return posed(cfg, fit, named, [named], t, log)


def warn_depth_scale(cfg: RunConfig, path, depth: np.ndarray | None, log=print) -> None:
    """A warning (`log`) when the first frame's readings are no depth camera's at the config's
    input.depth_scale (io.depth_scale_hint); `depth`: the frame at `path`, read if None."""
    if path is None:
        return
    try:
        depth = read_frame(cfg, path) if depth is None else depth
    except InputError:  # a bad frame is reported where frames are read
        return
    hint = depth_scale_hint(depth, cfg.inputs.depth_scale)
    if hint:
        log(f"warning: {path}: {hint}")


@dataclasses.dataclass
class CameraPrep:
    """One camera of a run before the engine: posed (a floor fit's report in `ground`), its
    background frames read, auto's sample of the run's frames, its full-resolution geometry."""

    camera: object
    ground: dict | None
    bg_files: list
    bg_frames: list
    sample: list
    geometry: object


def prepare_camera(cfg: RunConfig, frames: list[Path], dev: str, log=print) -> CameraPrep:
    """A camera's background frames read (a bad one is fatal), the first frame's depth scale
    looked at, auto's sample chosen, the pose fitted (extrinsics: auto) and the grid checked to
    be in view (with the fitted pose's warnings); `frames`: the camera's frames of the run."""
    auto_bg = cfg.inputs.auto_background
    bg_files = (expand(cfg.inputs.background, "input.background", cfg.inputs.topic, log)
                if cfg.inputs.background and not auto_bg else [])
    bg_frames = [read_frame(cfg, f) for f in bg_files]  # a bad one is fatal
    warn_depth_scale(cfg, bg_files[0] if bg_files else frames[0] if frames else None,
                     bg_frames[0] if bg_frames else None, log)
    sample = ([frames[i] for i in sample_frames(len(frames), cfg.inputs.background_auto.max_frames)]
              if auto_bg else [])
    camera, ground = cfg.camera, None
    if cfg.imu_tilt:
        log(f"camera {', '.join(f'{k[:-4]} {v:.2f} deg' for k, v in cfg.imu_tilt.items())} from the "
            f"{'camera' if is_live(cfg.inputs.frames) else 'recording'}'s accelerometer (camera.extrinsics leaves "
            f"{' and '.join(cfg.imu_tilt)} out)")
    if cfg.pose_auto:
        if auto_bg and len(sample) >= cfg.inputs.background_auto.min_frames:
            camera, ground = fit_pose_on_estimate(cfg, sample, dev, log)
        else:
            fit_on = bg_files or frames[:cfg.ground_frames]
            if not fit_on and is_live(cfg.inputs.frames):  # the Python API: no frame before detect
                raise ConfigError(f"camera.extrinsics: auto needs frames to fit the floor on, and a live camera "
                                  f"({cfg.inputs.frames}) has none before detect; expected the camera's pose "
                                  f"({{height: H}} with an accelerometer), input.background frames, or its first "
                                  f"frames as Detector.from_config's first_frames")
            if not fit_on:
                raise ConfigError("camera.extrinsics: auto needs frames to fit the floor on; expected "
                                  "input.frames or input.background, found neither")
            camera, ground = fit_camera_pose(cfg, fit_on, log)
    geometry = build_geometry(camera, cfg.grid, cfg.obj)  # full resolution: boxes, pictures
    if not np.any(geometry.rect_area > 0):  # a grid beside the view: every map would be empty
        c = camera.centre
        floor = (ground or {}).get("floor_xy")
        seen = f" ({floor_words(floor)})" if floor else ""
        raise ConfigError(
            f"grid: none of its {len(geometry.rect)} locations is in the camera's view (the camera "
            f"{'fitted ' if ground else ''}at x {c[0]:.2f} m, y {c[1]:.2f} m, {c[2]:.2f} m up); expected "
            f"grid.x and grid.y{' and grid.z' if cfg.grid.mode == 'voxel' else ''} over what the camera sees{seen}")
    if ground is not None:
        warn_fitted_pose(ground, geometry, log)
    return CameraPrep(camera, ground, bg_files, bg_frames, sample, geometry)


def warn_fitted_pose(ground: dict, geometry, log=print) -> None:
    """A floor fit that cannot be wrong quietly: pose_warnings logged and kept in its report."""
    warned = pose_warnings(ground, float(np.mean(geometry.rect_area > 0)), len(geometry.rect), ground.get("floor_xy"))
    for line in warned:
        log(f"warning: {line}")
    if warned:
        ground["warnings"] = warned


def camera_background(cfg: RunConfig, view, prep: CameraPrep, frames: list[Path], dev: str, parallel: bool,
                      log=print) -> tuple[str, tuple | None, dict | None, dict | None]:
    """A camera's background set in its engine.view.CameraView (set_up_background), with the
    static planes made background where it has no background frames (static_structure): (the
    run's words for it, what other workers take, auto's report, the planes' report or None)."""
    background, given, auto_report = set_up_background(cfg, view, prep.bg_frames, len(prep.bg_files), prep.sample,
                                                       dev, parallel, log)
    structure = None
    if not prep.bg_frames and cfg.inputs.structure.planes and frames:  # walls, cupboards, desks: background
        structure = static_structure(cfg, view, prep.camera, frames[:cfg.inputs.structure.frames], log)
        if structure["pixels"]:
            background += planes_words(structure)
            given = view.background_state()  # what other workers (--workers, Ray, live helpers) take
    prep.bg_frames.clear()
    return background, given, auto_report, structure


def planes_words(report: dict) -> str:
    """What the run's background words add for the static planes of a static_structure report."""
    return f"; {len(report['planes'])} static planes ({report['pixels']} pixels)"


def set_up_background(cfg: RunConfig, view, bg_frames: list, n_files: int, sample: list[Path], dev: str,
                      parallel: bool, log=print) -> tuple[str, tuple | None, dict | None]:
    """A camera's background (its engine.view.CameraView) from the background frames (brought to
    their median scale when they drift), `auto` from `sample`, or the floor; returns (the run's words for it, what other
    workers take: WorkerSpec.background, auto's report)."""
    auto_report, given = None, None
    if bg_frames:
        stack = view.resolution.frames(np.stack(bg_frames))
        if cfg.inputs.drift.correct and len(stack) > 1:  # drifting background frames brought to their median scale
            stack = stack / frame_scales([stack], cfg.inputs.drift)[:, None, None].astype(np.float32)
        view.set_background_frames(stack)
        given = (view.background(0), None) if parallel else None
        return f"{n_files} background frames", given, None
    if cfg.inputs.auto_background:
        if len(sample) >= cfg.inputs.background_auto.min_frames:
            log(f"estimating the background from {len(sample)} frames ...")
        estimator, auto_report = estimate_background(cfg, sample, view.height, view.width, dev,
                                                     view.resolution)
        given = estimator.result()  # (Background, fallback): also what other workers take
        view.set_background(*given)
        auto_report["fallback_pixels"] = view.fallback_pixels
        auto_report["fallback_share"] = view.fallback_pixels / view.n_pixels
        return (f"auto from {len(sample)} of the frames ({view.fallback_pixels} of "
                f"{view.n_pixels} pixels left to the floor-only model)"), given, auto_report
    return "floor plane only", None, None


def static_structure(cfg: RunConfig, view, camera, files: list, log=print) -> dict:
    """Large planes other than the floor in the median of `files` (frame files, or frames in
    metres at the camera's full resolution: a live camera's first) made background
    (structure.py) where a camera's background (its engine.view.CameraView) is the floor model
    (floor-only, or the pixels auto left to it); returns the report for summary.json's
    inference.structure."""
    from .model import Background
    from .structure import find_planes, median_frame, median_noise, plane_depths

    t = time.perf_counter()
    options, p = cfg.inputs.structure, cfg.model
    seen = median_frame([f if isinstance(f, np.ndarray) else read_frame(cfg, f) for f in files])
    taller = cfg.obj.height + 0.1 if cfg.grid.mode == "ground" else 0.0  # a plane no person is
    planes = find_planes(seen, camera, options, p.z_max, tuple(view.geometry.bounds[:4]), taller,
                         noise=median_noise(p.sensor_noise, len(files)))
    g, shape = view.geometry, (view.height, view.width)
    seen = view.resolution.frames(seen[None].astype(np.float32))[0]
    depth = (plane_depths(planes, g.rays, g.centre, options.margin, seen, 3 * options.distance) if planes
             else np.full(shape, np.inf))
    # where the frames read the plane, its reading there (a real wall bends by centimetres)
    on = np.isfinite(depth) & (seen > 0) & (np.abs(seen - depth) <= 3 * options.distance)
    depth = np.where(on, seen, depth)
    state = view.background_state()
    if state is None:  # floor-only: every pixel the floor model's
        bg = Background(np.zeros(shape), np.ones(shape), np.full(shape, p.missing_prob), np.ones(shape))
        fallback = np.ones(shape, bool)
    else:
        bg, fallback = state
        fallback = np.zeros(shape, bool) if fallback is None else fallback
    wall = fallback & np.isfinite(depth) & (depth <= p.z_max)  # (auto's own estimates are kept)
    if wall.any():
        bg.mu[wall] = depth[wall]
        bg.sigma[wall] = np.maximum(p.sensor_sigma(depth[wall]), options.distance / 3)
        bg.missing[wall], bg.outlier[wall] = p.missing_prob, p.outlier_prob
        view.set_background(bg, fallback & ~wall)
    report = {"frames": len(files), "planes": [x.report() for x in planes], "pixels": int(wall.sum()),
              "find_s": time.perf_counter() - t}
    if planes:
        log(f"static structure: {len(planes)} plane{'s' * (len(planes) > 1)} taken for background "
            f"({int(wall.sum())} of {view.n_pixels} pixels): "
            + ", ".join(f"{x['size_m'][0]:g} x {x['size_m'][1]:g} m" for x in report["planes"]))
    return report


def estimate_background(cfg: RunConfig, files: list[Path], height: int, width: int, device: str,
                        resolution: Resolution | None = None, chunk: int = 16):
    """input.background: auto over `files`, streamed `chunk` frames at a time, reduced by
    `resolution` (None: full resolution). Returns the estimator and a report."""
    t = time.perf_counter()
    estimator = BackgroundEstimator(height, width, cfg.model, cfg.inputs.background_auto, device)

    def chunks():
        for i in range(0, len(files), chunk):
            batch = np.stack([read_frame(cfg, f) for f in files[i:i + chunk]])
            yield resolution.frames(batch) if resolution else batch

    scales = frame_scales(chunks(), cfg.inputs.drift) if cfg.inputs.drift.correct else None
    done = 0
    for batch in chunks():
        if scales is not None:  # each frame brought to the frames' median scale before the clusters
            batch = batch / scales[done:done + len(batch), None, None].astype(np.float32)
        estimator.add(batch)
        done += len(batch)
    report = {"frames": len(files), "pixels": height * width, "memory_bytes": estimator.memory_bytes(),
              "estimate_s": time.perf_counter() - t}
    if scales is not None:
        report["drift_aligned"] = {"scale_min": round(float(scales.min()), 6),
                                   "scale_max": round(float(scales.max()), 6),
                                   "corrected": int(np.sum(scales != 1.0))}
    return estimator, report


def frame_scales(chunks, options) -> np.ndarray:
    """Each frame's depth scale against the frames' median one, for `auto` to estimate the
    background from aligned frames (drift.py): each frame's scale against the first frame's
    readings, then over their median; 1 where untrusted or within the dead band."""
    from .drift import background_sample, estimate_scale

    first, at, found = None, None, []
    for batch in chunks:
        for frame in batch:
            if first is None:
                first = frame.ravel()
                at = background_sample(first, first > 0)
            found.append(estimate_scale(frame.ravel()[at], first[at], options))
    trusted = [e.scale for e in found if e.trusted]
    middle = float(np.median(trusted)) if trusted else 1.0
    scales = np.array([e.scale / middle if e.trusted else 1.0 for e in found])
    scales[np.abs(scales - 1.0) <= options.deadband] = 1.0
    return scales


def refuse_low_view_from_above(cfg: RunConfig, fit, where: str) -> None:
    """camera.ground.up: auto (no IMU in the recording, none in the config): a plane facing the
    camera reads the same as a floor seen from straight down and as a wall faced level, and
    auto takes the floor. On a ground grid, a camera looking down (within 10 degrees of
    straight down) from lower than its objects' height sees none of them whole: the plane is
    taken for a wall, and the run stops with an InputError saying how to give the pose."""
    from .ground import AUTO_MARGIN_DEG, HINT

    if not isinstance(cfg.ground.up, str) or cfg.grid.mode != "ground":
        return
    if abs(fit.pitch_deg - 90.0) <= AUTO_MARGIN_DEG and fit.camera_height < cfg.obj.height:
        raise InputError(
            f"{where}: camera.extrinsics: auto: the floor found is a plane {fit.camera_height:.2f} m away facing "
            f"the camera; as a floor the camera would look down on it (pitch {fit.pitch_deg:.1f} deg) from lower "
            f"than the {cfg.obj.height:g} m objects it is to find, so it is more likely a wall the camera faces; "
            f"{HINT}, or give camera.extrinsics")


def fit_pose_on_estimate(cfg: RunConfig, files: list[Path], device: str, log=print):
    """camera.extrinsics: auto with background: auto: the floor is fitted on the estimated
    background at full resolution (the floor people hide in a frame shows in the estimate)."""
    from .ground import GroundFitError, fit_ground_frames

    t = time.perf_counter()
    log(f"fitting the floor on the background estimated from {len(files)} frames ...")
    estimator, _ = estimate_background(cfg, files, cfg.camera.height, cfg.camera.width, device)
    bg, fallback = estimator.result()
    depth = np.where(fallback | (bg.outlier >= 1), 0.0, bg.mu)
    try:
        fit = fit_ground_frames([depth], cfg.camera, cfg.ground)
    except GroundFitError as e:
        raise InputError(f"{files[0]} and {len(files) - 1} more frames: in their estimated "
                         f"background: {e}") from None
    refuse_low_view_from_above(cfg, fit, f"{files[0]} and {len(files) - 1} more frames (their estimated background)")
    fit = dataclasses.replace(fit, noise=None)  # a median of frames is quieter than the sensor
    return posed(cfg, fit, f"the background estimated on {len(files)} frames",
                 f"estimated background of {len(files)} frames", t, log)
