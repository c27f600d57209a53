"""The whole config file (`ConfigFile`), its JSON Schema (`dpom-warp schema`), which keys are
paths, and pydantic's errors said in one line."""

from __future__ import annotations

from pydantic import BaseModel, ConfigDict, Field, model_validator

from .camera import CameraSection
from .model_section import ModelSection
from .rig import RigCamera, RigSection
from .sections import (
    CountingSection,
    DetectionSection,
    LineSection,
    ZoneSection,
    EngineSection,
    EvaluationSection,
    GridSection,
    InputSection,
    ObjectSection,
    OutputSection,
    SyntheticSection,
    TrackingSection,
)
from ..values import Device, Node, PathValue, _fail


class ConfigFile(Node):
    """A dpom-warp run config (`dpom-warp run CONFIG`)."""

    model_config = ConfigDict(title="dpom-warp run config")

    device: Device = Field("auto", description="auto (first CUDA device, else the CPU), cpu, cuda, cuda:N")
    input: InputSection
    camera: CameraSection
    # a rig instead of input and camera (loading.rig_from_mapping validates it camera by camera)
    cameras: list[RigCamera] | None = Field(None, description=(
        "a rig: several cameras on one map, each {name, input, camera}, in place of input and camera "
        "(docs/rig.md)"))
    rig: RigSection = RigSection()
    grid: GridSection
    object: ObjectSection = ObjectSection()
    model: ModelSection = ModelSection()
    detection: DetectionSection = DetectionSection()
    evaluation: EvaluationSection = EvaluationSection()
    tracking: TrackingSection = TrackingSection()
    output: OutputSection = OutputSection()
    engine: EngineSection = EngineSection()
    synthetic: SyntheticSection | None = None
    zones: list[ZoneSection] = Field([], description="zones on the floor whose tracks are counted every frame "
                                                     "(docs/zones.md)")
    lines: list[LineSection] = Field([], description="counting lines on the floor whose crossings are recorded")
    counting: CountingSection = CountingSection()

    @model_validator(mode="after")
    def _across_sections(self):
        grid, obj = self.grid, self.object
        sizes = [("x", "width", obj.width), ("y", "depth" if obj.depth else "width", obj.depth or obj.width)]
        if grid.mode == "voxel":
            sizes.append(("z", "height", obj.height))
        for axis, key, size in sizes:
            lo, hi, _ = getattr(grid, axis)
            if size > hi - lo:
                raise _fail(f"expected at most the grid's {axis} extent {hi - lo:g} m, found {size:g}",
                            f"object.{key}")
        heights = self.model.top_heights or ()
        if grid.mode == "voxel" and heights:
            raise _fail(f"expected [] in voxel mode (no top-band test there), found {list(heights)}",
                        "model.top_heights")
        if any(h >= obj.height for h in heights):
            raise _fail(f"expected heights below object.height ({obj.height:g} m), found {list(heights)}",
                        "model.top_heights")
        check_zones(self.zones, self.lines, grid)
        if (self.zones or self.lines) and self.tracking.method == "off":
            raise _fail("zones and lines count the tracks; expected tracking.method ksp, online or auto, found off",
                        "tracking.method")
        if self.synthetic is not None and self.camera.extrinsics == "auto":
            raise _fail("rendering needs a camera pose; expected camera.extrinsics given as "
                        "{height, pitch_deg, ...} or a matrix, found auto", "synthetic")
        return self


def check_zones(zones, lines, grid) -> None:
    """Zones and lines that mean something: a polygon of 3 points or more that does not cross
    itself, a line of some length, names unique, each meeting the grid's rectangle."""
    import numpy as np

    from ..zones import meets_rectangle, self_crossing

    rect = (grid.x[0], grid.x[1], grid.y[0], grid.y[1])
    for kind, items in (("zones", zones), ("lines", lines)):
        seen = {}
        for i, item in enumerate(items):
            if item.name in seen:
                raise _fail(f"expected a name unlike the other {kind}', found {item.name!r} again ({kind}[{seen[item.name]}])",
                            f"{kind}[{i}].name")
            seen[item.name] = i
            if kind == "zones":
                pts = np.asarray(item.polygon, float)
                if len(pts) < 3:
                    raise _fail(f"expected at least 3 points [x, y], found {len(pts)}", f"zones[{i}].polygon")
                crossed = self_crossing(pts)
                if crossed is not None:
                    a, b = crossed
                    raise _fail(f"expected a polygon that does not cross itself, found its edges {a} and {b} meeting "
                                f"(points {a}-{(a + 1) % len(pts)} and {b}-{(b + 1) % len(pts)})", f"zones[{i}].polygon")
            else:
                pts = np.array([item.start, item.end], float)
                if np.allclose(pts[0], pts[1]):
                    raise _fail(f"expected a line of some length, found from and to both {list(item.start)}",
                                f"lines[{i}]")
            if not meets_rectangle(pts, rect, kind == "zones"):
                raise _fail(f"expected a {kind[:-1]} over the grid (x {rect[0]:g} to {rect[1]:g} m, y {rect[2]:g} to "
                            f"{rect[3]:g} m), found it wholly outside", f"{kind}[{i}]")


def json_schema() -> dict:
    """The JSON Schema of a run config (what `dpom-warp schema` writes)."""
    schema = ConfigFile.model_json_schema()
    # width, height and intrinsics may come from camera.file or a recording, the whole section
    # from a recording (parse_config says when they come from neither), and `camera: FILE` is
    # short for {file: FILE}
    schema["$defs"]["CameraSection"].pop("required", None)
    schema["required"] = [k for k in schema["required"] if k not in ("camera", "input")]
    schema["oneOf"] = [{"required": ["input"], "not": {"required": ["cameras"]}},
                       {"required": ["cameras"], "not": {"anyOf": [{"required": ["input"]}, {"required": ["camera"]}]}}]
    schema["properties"]["camera"] = {"anyOf": [
        {"$ref": "#/$defs/CameraSection"},
        {"type": "string", "description": "a camera file: short for {file: FILE}"}]}
    return {"$schema": "https://json-schema.org/draft/2020-12/schema", **schema}


def path_keys(model: type[BaseModel] = ConfigFile, prefix: str = "") -> list[str]:
    """Dotted keys of the config values that are paths (PathValue), from the models."""
    keys = []
    for name, info in model.model_fields.items():
        key = f"{prefix}{name}"
        if any(isinstance(m, PathValue) for m in info.metadata) or _has_path(info.annotation):
            keys.append(key)
        for sub in _sections(info.annotation):
            keys += path_keys(sub, key + ".")
    return keys


def _args(tp):
    return getattr(tp, "__args__", ()) or ()


def _has_path(tp) -> bool:
    meta = getattr(tp, "__metadata__", ())
    return any(isinstance(m, PathValue) for m in meta) or any(_has_path(a) for a in _args(tp))


def _sections(tp) -> list[type[BaseModel]]:
    if isinstance(tp, type) and issubclass(tp, Node):
        return [tp]
    return [s for a in _args(tp) for s in _sections(a)]


# -- errors as one line -------------------------------------------------------------------------
