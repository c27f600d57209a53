"""The config's other sections: input, grid, object, detection, evaluation, tracking, output,
engine and synthetic (the camera and the model have files of their own)."""

from __future__ import annotations

from typing import Annotated, Literal, Union

from pydantic import ConfigDict, Field, model_validator

from ..detect import EDGE_RADIUS, GIVE_WAY, MIN_LOG_ODDS
from ..drift import DriftOptions
from ..structure import StructureOptions
from ..geometry import Grid
from ..shapes import ObjectBox
from ..model import AutoBackground
from ..resolution import REDUCERS
from ..scene_spec import SceneSpec
from ..tracking import TrackingOptions
from ..values import (
    Batch,
    Bool,
    FilePath,
    Int,
    Node,
    Num,
    Pair,
    Str,
    Stride,
    Switch,
    _fail,
    _fmt,
)


BackgroundAutoSection = AutoBackground  # declared by its owner (model.py)


class InputSection(Node):
    """The depth frames and the background."""

    frames: FilePath | None = Field(None, description="glob (or folder) of depth frames (16-bit PNG or .npy, "
                                                      "in depth units), processed in sorted order, or a "
                                                      "recording (.bag, .db3, .mcap, a ROS 2 bag folder, "
                                                      ".mkv); required by dpom-warp run")
    background: Union[Literal["auto"], FilePath, None] = Field(
        None, description="glob (or folder) of background frames (no people); auto: estimated from the "
                          "run's own frames; null: the floor-only background")
    depth_scale: Num = Field(0.001, gt=0, description="metres per unit of the files' values; 0 = no "
                                                      "reading (default: the recording's, else 0.001)")
    topic: Str | None = Field(None, description="a recording's depth stream (default: its only one)")
    stride: Stride = Field("auto", description="inference on blocks of stride x stride pixels; auto: the "
                                               "coarsest stride (up to 8) leaving 6 pixels across the "
                                               "object at the farthest cell; pictures, boxes and the "
                                               "floor fit stay at full resolution")
    reduce: Literal[REDUCERS] = Field("median", description="how a block becomes one reading: median "
                                                            "(lower median of its readings), nearest "
                                                            "(one pixel), min")
    fps: Num = Field(15.0, gt=0, description="frames per second of the frames (tracking's speeds)")
    play: bool = Field(False, description="send the frames (files at input.fps, a recording at its "
                                          "timestamps) as a live camera would: the newest frame inferred, "
                                          "the others dropped, tracks online (live mode tried without a "
                                          "camera; --play)")
    background_auto: BackgroundAutoSection = BackgroundAutoSection()
    drift: DriftOptions = DriftOptions()
    structure: StructureOptions = StructureOptions()

    @property
    def auto_background(self) -> bool:
        return self.background == "auto"


GridSection = Grid  # declared by its owner (geometry.py)
ObjectSection = ObjectBox  # declared by its owner (geometry.py)


class DetectionSection(Node):
    """Detections from the rho* map."""

    threshold: Num = Field(0.5, gt=0, lt=1, description="minimum rho* of a detection (a local maximum)")
    nms_radius: Num = Field(0.4, ge=0, description="greedy non-maximum suppression: a weaker maximum closer than "
                                                   "this (by more than rounding) goes, metres")
    edge_radius: Num | None = Field(None, ge=0, description=(
        "a detection whose silhouette is mostly outside the image (its share in view under edge_view) is dropped "
        "within this distance of one in view, metres (in a rig: of every camera that does not see it behind that "
        f"one; docs/rig.md); default {EDGE_RADIUS:g} on ground "
        f"grids, 0 (off) in voxel mode"))
    edge_view: Num = Field(0.5, gt=0, le=1, description=(
        "the share of a silhouette's rectangle inside the image under which edge_radius applies"))
    give_way: Num = Field(GIVE_WAY, ge=0, le=1, description=(
        "in a rig of several cameras: a detection of at least this rho* whose suppression takes two cells of at "
        "least this rho* that are not within nms_radius of each other stands between two people and gives way to "
        "them (docs/rig.md); 0: off. One camera: no effect"))
    min_log_odds: Num = Field(MIN_LOG_ODDS, ge=0, description=(
        "the joint test: a detection whose log posterior odds, with the other detections present and nothing "
        "else, is under this (nats) leaves the map (README, How it works); 0: off"))

    def build(self, grid_mode: str) -> DetectionSection:
        """The section with edge_radius chosen for the grid where it is null."""
        if self.edge_radius is not None:
            return self
        return self.model_copy(update={"edge_radius": EDGE_RADIUS if grid_mode == "ground" else 0.0})


class EvaluationSection(Node):
    """Scores against ground truth."""

    ground_truth: FilePath | None = Field(None, description="ground-truth JSON; scores go into summary.json")
    match_distance: Num = Field(0.5, gt=0, description="matching gate on the ground plane, metres")
    hidden_visibility: Num = Field(0.1, ge=0, le=1,
                                   description="people less visible than this are not penalised in "
                                               "the second protocol")
    plots: Bool = Field(False, description="also write the evaluation figures into plots/")


TrackingSection = TrackingOptions  # declared by its owner (tracking.py)


class OutputSection(Node):
    """What the run writes."""

    dir: FilePath = Field("runs/out", description="output folder (--output overrides)")
    images: Bool = Field(True, description="a picture per frame")
    images_every: Int = Field(1, ge=1, description="a picture of every Nth frame done (the 1st, the "
                                                   "N+1th, ...; a long recording's run draws fewer)")
    rerun: FilePath | None = Field(None, description="also write a Rerun recording (.rrd) here: depth, "
                                                     "boxes, map and tracks per frame (the view extra)")
    ply: Bool = Field(False, description="the frame's points and the detected boxes as .ply files")
    view: Bool = Field(False, description="show the run in a spawned Rerun viewer as it goes (--view; the view "
                                          "extra)")


class EngineSection(Node):
    """The Warp engine's buffers and launches."""

    entries_per_pixel: Num = Field(8.0, gt=0, description="initial mask-list capacity per pixel")
    max_entries: Int | None = Field(None, ge=1, description="hard cap on the list capacity; a frame "
                                                            "above it is refused, never truncated")
    memory_gb: Num | None = Field(8.0, gt=0, description="memory budget of the engine's buffers, GiB")
    batch: Batch = Field("auto", description="frames per engine call; auto: 16 for a recorded run on a GPU "
                                             "(fewer where engine.memory_gb holds fewer), else 1 (the CPU, a "
                                             "live camera, the Python API)")
    graph: Annotated[Literal["auto", "on", "off"], Switch] = Field("auto", description="replay the iteration loop as a "
                                                                    "captured graph; auto: on CUDA only")
    exact: Bool = Field(False, description="the exact path: full resolution, every pass full, no warm "
                                           "start (the NumPy reference's results to 1e-6)")
    mask_index: Literal["auto", "table", "tiles"] = Field(
        "auto", description="the static index the mask lists are built from (the same lists): table: "
                            "every silhouette pixel's object depth stored; tiles: image tiles, less "
                            "memory; auto: the table with a solid where it takes <= 256 MiB and fits "
                            "memory_gb")


class SyntheticSection(SceneSpec):
    """Render a synthetic sequence before the run (once; later runs reuse it)."""

    cache: FilePath = Field(description="folder of the rendered frames, background, ground truth (the objects "
                                        "seen) and trajectories.json (every object every frame, hidden or not)")

    def spec(self) -> SceneSpec:
        """What to render (the scene without the folder it is kept in)."""
        return SceneSpec(**self.model_dump(exclude={"cache"}))


class ZoneSection(Node):
    """A zone on the floor: the tracks inside it are counted every frame (zones.csv)."""

    name: Str = Field(description="the zone's name (zones.csv, dwell.csv, summary.json)")
    polygon: list[Pair] = Field(description="[[x, y], ...] world metres on the floor, at least 3 points, "
                                            "not crossing itself; a point on its edge is inside")


class LineSection(Node):
    """A counting line on the floor: each track crossing it is a row of crossings.csv."""

    model_config = ConfigDict(extra="forbid", frozen=True, populate_by_name=True)

    name: Str = Field(description="the line's name (crossings.csv, summary.json)")
    start: Pair = Field(alias="from", description="[x, y] world metres: one end")
    end: Pair = Field(alias="to", description="[x, y] the other end; in: from the right of from->to to its left")

    @model_validator(mode="before")
    @classmethod
    def _mapping(cls, raw):  # its keys are `from` and `to` (Python words: the fields are start and end)
        if not isinstance(raw, dict):
            raise _fail(f"expected a mapping {{name, from, to}}, found {_fmt(raw)}")
        unknown = [str(k) for k in raw if k not in ("name", "from", "to")]
        if unknown:
            raise _fail("unknown key (expected one of name, from, to)", unknown[0])
        return raw


class CountingSection(Node):
    """How zones and lines count the tracks."""

    hysteresis: Num = Field(0.05, ge=0, description="metres: a track changes side of a line only once this far "
                                                    "beyond it, so one that jitters on the line is counted once "
                                                    "(docs/zones.md: the measured trade-off)")
    events: FilePath | None = Field(None, description="also stream each committed frame's counts and crossings as "
                                                      "JSON lines to this file (-: standard output; --events)")
