"""A run's outputs, one writer each: maps, pictures, PLY, frame records, the Rerun log,
detections.csv, the tracks' tables and summary.json. `writers_for` chooses them from the config;
the recorded run (pipeline, its frames inferred here, by --workers processes or Ray actors) and
the live run feed the same writers the same three events, in frame order:

- `frame(done)`: a frame's result is in (its map, record and the files its worker drew);
- `tracked(done, shown)`: the frame's tracks are final (`shown`: ShownTracks.at's list; None
  with tracking off): after the run's KSP, or as the live run's online tracker commits it;
- `finish(end)`: the run is over (RunEnd: the frames done, their records, the tracks).

A frame is done when its record is written (Records, after the frame's other files): --resume
and a reader of a live run's folder count on it. A new output is one class here and one line
in `writers_for`.
"""

from __future__ import annotations

import dataclasses
import time
from functools import cached_property
from pathlib import Path

import numpy as np

from .config import RunConfig
from .zone_tables import ZoneTables
from .io import read_depth, write_bytes_atomic, write_json_atomic, write_npy_atomic, write_text_atomic

CSV_HEADER = "frame,x,y,z,rho,u0,v0,u1,v1"
TRACK_FILES = ("tracks.csv", "track_table.csv")


@dataclasses.dataclass
class RunView:
    """What the writers know of the run: its config, output folder, full-resolution geometry
    and posed camera; `worker_pictures`: the frames' workers draw the pictures (no tracks on
    them, one a frame), else they are drawn once the tracks are final."""

    cfg: RunConfig
    out: Path
    geometry: object
    camera: object = None
    worker_pictures: bool = False


class FrameDone:
    """A frame whose result is in. `index`: its place among the frames the run wrote, from 0
    (a picture is due at every output.images_every-th); `map`: as maps/ holds it (float32), or
    a function that loads it; `files`: output-relative path -> bytes its worker drew (pictures
    without tracks, PLY); `result_dets`: the detections of the engine's result, where the loop
    has them (the joint test's); `depth` (metres) where the loop has it, else read from `path`
    when a writer asks; `dets`: the map's detections, as a finished run draws them."""

    def __init__(self, run: RunView, index: int, name: str, stem: str, timestamp: float | None, map,
                 record: dict | None = None, files: dict | None = None, result_dets: list | None = None,
                 depth: np.ndarray | None = None, path: Path | None = None, truth: list | None = None):
        self.run, self.index, self.name, self.stem, self.timestamp = run, index, name, stem, timestamp
        self._map, self.record, self.files, self.path, self.truth = map, record, files or {}, path, truth
        self.result_dets, self.started = result_dets, None
        if depth is not None:
            self.__dict__["depth"] = depth

    @property
    def has_depth(self) -> bool:
        return "depth" in self.__dict__

    @cached_property
    def map(self) -> np.ndarray:
        return self._map() if callable(self._map) else self._map

    @cached_property
    def rho_map(self) -> np.ndarray:
        return self.map.reshape(self.run.cfg.grid.shape)

    @cached_property
    def dets(self) -> list:
        from .detect import detect_map

        return detect_map(self.rho_map, self.run.geometry, self.run.cfg.detection)

    @cached_property
    def depth(self) -> np.ndarray:
        cfg = self.run.cfg
        if cfg.is_rig:  # a rig's frame (frames.RigFrame): one depth a camera
            from .worker import read_rig_frame

            return read_rig_frame(cfg, self.path.paths)
        return read_depth(self.path, cfg.inputs.depth_scale, (cfg.camera.height, cfg.camera.width))

    @property
    def picture_due(self) -> bool:
        cfg = self.run.cfg
        return cfg.output.images and self.index % cfg.output.images_every == 0


@dataclasses.dataclass
class RunEnd:
    """A run's frames done (names, in order), their records, and its tracks (None: not
    tracked) over those frames at `fps` (`times`: their timestamps); `summary`: summary.json's
    content, filled in before Summary writes it."""

    names: list[str]
    records: dict
    tracks: list | None = None
    fps: float | None = None
    times: list | None = None
    summary: dict | None = None


class Writer:
    """One output of a run; each event does nothing unless the writer's output needs it.
    `parallel`: its `tracked` may run on several threads at once (a recorded run draws its
    frames two at a time); `wants_tracked`: the writer does something on `tracked` (a
    recorded run goes over its frames after tracking only for those)."""

    parallel = False
    wants_tracked = False

    def __init__(self, run: RunView):
        self.run = run

    def prefetch(self, done: FrameDone) -> None:
        """What `tracked` will read of the frame, read ahead on a drawing thread."""

    def frame(self, done: FrameDone) -> None:
        pass

    def tracked(self, done: FrameDone, shown: list | None) -> None:
        pass

    def finish(self, end: RunEnd) -> None:
        pass

    def close(self) -> None:
        """The run ended early (an error, Ctrl-C): what the writer holds open is closed; the
        files written stay."""


class Maps(Writer):
    """maps/<stem>.npy: each frame's occupancy map (rho*, float32, grid-shaped)."""

    def frame(self, done):
        write_npy_atomic(self.run.out / "maps" / f"{done.stem}.npy", done.map)


class Files(Writer):
    """The files a frame's worker drew under `folder`/ (images/: pictures without tracks;
    ply/: points and boxes)."""

    def __init__(self, run: RunView, folder: str):
        super().__init__(run)
        self.prefix = folder + "/"

    def frame(self, done):
        for rel, data in done.files.items():
            if rel.startswith(self.prefix):
                write_bytes_atomic(self.run.out / rel, data)


class Pictures(Files):
    """images/<stem>.png: a frame's picture, drawn by its worker without tracks, or with its
    tracks and trails once they are final (of every output.images_every-th frame; another
    frame's picture left by an earlier drawing is removed)."""

    parallel = True

    def __init__(self, run: RunView):
        super().__init__(run, "images")
        self.wants_tracked = not run.worker_pictures
        # with zones or lines each picture shows their counts so far, which ZoneTables (before
        # this writer) has put on the frame: the pictures are drawn in frame order after it
        self.parallel = not (run.cfg.zones or run.cfg.lines)

    def tracked(self, done, shown):
        if not self.wants_tracked:
            return
        path = self.run.out / "images" / f"{done.stem}.png"
        if not done.picture_due:
            path.unlink(missing_ok=True)
            return
        write_bytes_atomic(path, tracked_picture(self.run.cfg, self.run.geometry, done.depth, done.rho_map,
                                                 done.dets, done.name, done.truth, shown,
                                                 getattr(done, "zone_overlay", None)))


class Records(Writer):
    """frames/<stem>.json, written last of a frame's files: the frame is done. Its stats get
    `write_s`, the time since the frame's first file was written (`started`)."""

    def frame(self, done):
        done.record["stats"]["write_s"] = time.perf_counter() - done.started
        write_json_atomic(self.run.out / "frames" / f"{done.stem}.json", done.record)


class Rerun(Writer):
    """The Rerun log (output.rerun's .rrd, a viewer with output.view): a frame's depth, map and
    boxes when it is in and the loop has its depth (a live run), its tracks when final (with
    the frame itself where it was not logged then)."""

    wants_tracked = True

    def __init__(self, run: RunView):
        from .view import RerunLog

        super().__init__(run)
        self.log = RerunLog(run.cfg.output.rerun, spawn=run.cfg.output.view)
        if run.cfg.is_rig:  # each camera at world/cameras/NAME
            self.log.camera(run.camera or [m.camera for _, m in run.cfg.cameras], run.cfg.camera_names,
                            run.geometry.parts)
        else:
            self.log.camera(run.camera or run.cfg.camera)
        self.logged: set[int] = set()
        self.closed = False

    def frame(self, done):
        if done.has_depth:
            dets = done.result_dets if done.result_dets is not None else done.dets
            self.log.frame(done.index, done.timestamp, done.depth, dets, done.rho_map)
            self.logged.add(done.index)

    def prefetch(self, done):
        if done.index not in self.logged:
            done.depth, done.dets  # noqa: B018 - read on the drawing thread

    def tracked(self, done, shown):
        if done.index in self.logged:
            self.log.tracks(done.index, done.timestamp, done.dets, shown)
            self.logged.discard(done.index)
        else:
            self.log.frame(done.index, done.timestamp, done.depth, done.dets, done.rho_map, shown)
        overlay = getattr(done, "zone_overlay", None)
        if overlay:  # zones and lines with their counts (ZoneTables, before this writer)
            self.log.zones(done.index, done.timestamp, overlay)

    def finish(self, end):
        self.close()

    def close(self):
        if not self.closed:
            self.closed = True
            self.log.close()


class DetectionsCsv(Writer):
    """detections.csv: every frame's detections, in frame order (frame,x,y,z,rho,u0,v0,u1,v1)."""

    def finish(self, end):
        rows = [CSV_HEADER] + [r for n in end.names for r in end.records[n]["rows"]]
        write_text_atomic(self.run.out / "detections.csv", "\n".join(rows) + "\n")


class TrackTables(Writer):
    """tracks.csv and track_table.csv of the run's tracks; none (and an earlier run's removed)
    where the run is not tracked."""

    def finish(self, end):
        if end.tracks is None:
            for name in TRACK_FILES:
                (self.run.out / name).unlink(missing_ok=True)
            return
        track_table_files(self.run.out, end.tracks, end.names, end.fps, end.times)


class Summary(Writer):
    """summary.json: the run's settings, timings, per-frame records and scores; written last."""

    def finish(self, end):
        write_json_atomic(self.run.out / "summary.json", jsonable(end.summary))


class Writers:
    """The writers of a run, fed in order: each event goes to each writer in turn."""

    def __init__(self, writers: list[Writer]):
        self.writers = writers

    def frame(self, done: FrameDone) -> dict:
        """A frame's files, its record last; returns the record."""
        done.started = time.perf_counter()
        for w in self.writers:
            w.frame(done)
        return done.record

    def tracked(self, done: FrameDone, shown: list | None) -> None:
        for w in self.writers:
            w.tracked(done, shown)

    def tracked_all(self, frames: list, shown: list) -> None:
        """Every frame's tracks final at once (a recorded run's, once tracked): `frames` gives
        FrameDone(i) for each i. The parallel writers draw two frames at a time (PNG encoding and
        Pillow's drawing release the GIL, so on two cores one is drawn while the other is
        encoded), the others take each frame in order; 64 frames in flight at most."""
        from concurrent.futures import ThreadPoolExecutor

        wanting = [w for w in self.writers if w.wants_tracked]
        if not wanting:
            return
        parallel = [w for w in wanting if w.parallel]
        serial = [w for w in wanting if not w.parallel]

        def draw(done):
            for w in parallel:
                w.tracked(done, shown[done.index])
            for w in serial:
                w.prefetch(done)
            return done

        with ThreadPoolExecutor(2) as pool:
            for start in range(0, len(shown), 64):
                for done in pool.map(draw, [frames(i) for i in range(start, min(len(shown), start + 64))]):
                    for w in serial:
                        w.tracked(done, shown[done.index])

    def finish(self, end: RunEnd) -> None:
        for w in self.writers:
            w.finish(end)

    def has(self, kind: type) -> bool:
        return any(isinstance(w, kind) for w in self.writers)

    def close(self) -> None:
        """A run that ends early: what the writers hold open closed (the files written stay)."""
        for w in self.writers:
            w.close()


def writers_for(run: RunView, rerun: bool = True) -> Writers:
    """The writers the config asks for, in the order they write (a frame's record after its
    other files; summary.json last). `rerun`: False where the Rerun log is opened later (a
    recorded run's, once its frames are tracked)."""
    cfg = run.cfg
    chosen: list[Writer] = [Maps(run), ZoneTables(run)]  # (the zones' counts before the pictures show them)
    if cfg.output.images:
        chosen.append(Pictures(run))
    if cfg.output.ply:
        chosen.append(Files(run, "ply"))
    chosen.append(Records(run))
    if rerun and (cfg.output.rerun or cfg.output.view):
        chosen.append(Rerun(run))
    chosen += [DetectionsCsv(run), TrackTables(run), Summary(run)]
    return Writers(chosen)


def tracked_picture(cfg: RunConfig, geometry, depth, rho_map, dets, name: str, truth, shown,
                    overlay: dict | None = None) -> bytes:
    """A frame's picture with the tracks `shown` on it (ShownTracks; None: no tracks) and the
    zones and lines with their counts (`overlay`, ZoneTables'), as a finished run and a live run
    draw it."""
    if cfg.is_rig:
        from .render_rig import rig_picture

        return rig_picture(depth, rho_map, cfg, geometry, dets, truth, name, tracks=shown, overlay=overlay)
    from .render import frame_picture

    return frame_picture(depth, rho_map, cfg.grid, dets, geometry.centre[:2], truth, name,
                         in_view=geometry.rect_area > 0, tracks=shown, trail=cfg.tracking.trail, overlay=overlay)


def track_table_files(out: Path, tracks, names: list[str], fps: float, times: list | None = None) -> None:
    """tracks.csv and track_table.csv of `tracks` over the frames `names` (`times`: their
    timestamps, None where unknown)."""
    from .track_files import track_table, tracks_csv

    write_text_atomic(out / "tracks.csv", tracks_csv(tracks, names))
    write_text_atomic(out / "track_table.csv", track_table(tracks, names, fps, times))


def jsonable(x):
    """`x` with NumPy numbers as Python's and non-finite floats as None (JSON has neither)."""
    if isinstance(x, dict):
        return {k: jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [jsonable(v) for v in x]
    if isinstance(x, (np.floating, float)):
        return None if not np.isfinite(x) else float(x)
    if isinstance(x, np.integer):
        return int(x)
    return x
