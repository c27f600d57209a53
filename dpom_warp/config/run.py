"""The typed run config the pipeline uses (`RunConfig`), made from a validated config file by
`parse_config`, which reads no file: the defaults that depend on other keys are chosen here."""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Any

from pydantic import ValidationError

from ..geometry import Camera, Grid
from ..shapes import ObjectBox
from ..ground import GroundOptions
from ..model import ModelParams
from ..scene_spec import SceneSpec
from ..tracking import TrackingOptions
from .schema import ConfigFile
from .sections import DetectionSection, EngineSection, EvaluationSection, InputSection, OutputSection
from ..values import ConfigError, _first_error


# -- the typed run config the pipeline uses ----------------------------------------------------
# The run uses these sections as validated (each field declared once, in config/sections.py);
# parse_config fills in the values that depend on other keys (detection.edge_radius, the exact
# path's stride, engine.batch once a run chooses it).
Inputs, Output, EngineOptions, Detection, Evaluation = (InputSection, OutputSection, EngineSection, DetectionSection,
                                                        EvaluationSection)


@dataclass
class RunConfig:
    """A validated run configuration; `resolved` is the config with every default filled in.

    With `pose_auto` (camera.extrinsics: auto) the camera's pose is a placeholder until the
    run fits the floor with `ground` options on `ground_frames` frames.
    """

    device: str
    inputs: Inputs
    camera: Camera
    grid: Grid
    obj: ObjectBox
    model: ModelParams
    detection: Detection
    evaluation: Evaluation
    output: Output
    engine: EngineOptions
    synthetic: SceneSpec | None
    synthetic_cache: str | None
    resolved: dict
    pose_auto: bool = False
    ground: GroundOptions = GroundOptions()
    ground_frames: int = 5
    tracking: TrackingOptions = TrackingOptions()
    # where the values came from (loading.load_config): the config file, and the --set items
    origin: dict = field(default_factory=dict)
    # a rig (`cameras:`): (name, the camera's own RunConfig: the shared sections with its input
    # and camera), in the config's order; the rig's inputs and camera are the first camera's
    cameras: tuple = ()
    rig: Any = None  # config.rig.RigSection of a rig
    zones: tuple = ()  # config.sections.ZoneSection each
    lines: tuple = ()  # config.sections.LineSection each
    counting: Any = None  # config.sections.CountingSection
    # camera.extrinsics' pitch_deg and roll_deg that the config left out and the recording's
    # accelerometer gave (loading.tilt_from_gravity), by key
    imu_tilt: dict = field(default_factory=dict)

    @property
    def is_rig(self) -> bool:
        """A config with a `cameras:` list (of one camera or more)."""
        return bool(self.cameras)

    @property
    def camera_names(self) -> list[str]:
        """A rig's camera names in the config's order (none for a single-camera config)."""
        return [name for name, _ in self.cameras]

    def members(self) -> list[tuple[str, "RunConfig"]]:
        """(name, RunConfig) of each camera: a rig's, else this config's own camera ("camera")."""
        return list(self.cameras) or [("camera", self)]

    def source_of(self, key: str) -> str:
        """Where the value of `key` came from: `--set KEY=VALUE`, else the config file."""
        return source_of(key, self.origin.get("set", ()), self.origin.get("file") or "config")

    @property
    def live(self) -> bool:
        """A live run: a camera (input.frames: realsense[:SERIAL]) or frames played as one."""
        from ..names import is_live

        return self.inputs.play or (self.inputs.frames is not None and is_live(self.inputs.frames))

    def blame(self, message: str) -> str:
        """An error about a config key (`KEY: ...`) said with where its value came from."""
        key = config_key(message)
        return f"{self.source_of(key)}: {message}" if key else message


KEY_AT_START = re.compile(r"^([a-z_]+(?:\[\d+\])?(?:\.[a-z_]+(?:\[\d+\])?)*): ")


def config_key(message: str) -> str | None:
    """The config key an error message starts with (`input.frames: ...`), else None."""
    m = KEY_AT_START.match(message)
    return m.group(1) if m else None


def source_of(key: str, overrides, file: str) -> str:
    """`--set ITEM` where an override set `key` (or a section above it, or a key inside it), else `file`."""
    key = re.sub(r"\[(\d+)\]", r".\1", key)  # cameras[1].input.frames as --set writes it
    for item in overrides:
        k = item.split("=", 1)[0].strip()
        if key == k or key.startswith(k + ".") or k.startswith(key + "."):
            return f"--set {item}"
    return file


def parse_config(raw: dict[str, Any]) -> RunConfig:
    """Validate a config mapping into a RunConfig. No file is read: the camera keys a camera file
    or a recording gives are filled in before (loading.config_from_mapping; a run folder's
    run.json has them all)."""
    if isinstance(raw, dict) and "cameras" in raw:  # a rig: camera by camera
        from .rig import parse_rig

        return parse_rig(raw, parse_config)
    try:
        c = ConfigFile.model_validate(raw)
    except ValidationError as e:
        raise ConfigError(_first_error(e)) from None
    inputs = c.input
    cam = c.camera
    camera, pose_resolved = cam.build()
    ground = cam.ground.options()
    grid = c.grid
    obj = c.object
    model = c.model.build(c.grid.mode, c.object.shape, c.object.height, c.input.background is not None,
                          c.engine.exact)
    detection = c.detection.build(c.grid.mode)
    evaluation, output, engine = c.evaluation, c.output, c.engine
    tracking = c.tracking
    if engine.exact:  # the exact path: full resolution, every pass full, no warm start
        inputs = inputs.model_copy(update={"stride": 1})
    synthetic = c.synthetic.spec() if c.synthetic is not None else None
    cache = c.synthetic.cache if c.synthetic is not None else None

    def plain(v):
        return list(v) if isinstance(v, tuple) else v

    resolved = {
        "device": c.device,
        "input": inputs.model_dump(),
        "camera": {"width": cam.width, "height": cam.height,
                   "intrinsics": cam.intrinsics.model_dump(),
                   "extrinsics": pose_resolved,
                   "distortion": list(cam.distortion) if cam.distortion else None,
                   "ground": {"frames": cam.ground.frames, **{k: plain(v) for k, v in ground.model_dump().items()}}},
        "grid": {"mode": grid.mode, "x": list(grid.x), "y": list(grid.y), **({"z": list(grid.z)} if grid.z else {})},
        "object": obj.model_dump(),
        "model": {k: plain(v) for k, v in model.model_dump().items()},
        "detection": detection.model_dump(), "evaluation": evaluation.model_dump(),
        "tracking": {**tracking.model_dump(), "regions": [list(r) for r in tracking.regions]},
        "output": output.model_dump(), "engine": engine.model_dump(),
    }
    if synthetic is not None:
        resolved["synthetic"] = {"cache": cache, **{k: plain(v) for k, v in synthetic.model_dump().items()}}
    if c.zones or c.lines:  # (a config without them resolves as before)
        resolved["zones"] = [{"name": z.name, "polygon": [list(p) for p in z.polygon]} for z in c.zones]
        resolved["lines"] = [{"name": x.name, "from": list(x.start), "to": list(x.end)} for x in c.lines]
        resolved["counting"] = c.counting.model_dump()
    return RunConfig(c.device, inputs, camera, grid, obj, model, detection, evaluation, output,
                     engine, synthetic, cache, resolved, cam.extrinsics == "auto", ground, cam.ground.frames, tracking,
                     zones=tuple(c.zones), lines=tuple(c.lines), counting=c.counting)

