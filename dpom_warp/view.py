"""A Rerun recording of a run (`output.rerun: PATH.rrd`) or a live viewer (`--view`): per frame,
the depth image seen through the posed camera (so the viewer shows it in 3D), the detection
boxes with identities and rho*, the occupancy map, and the tracks with their trails.

Entities: `world/camera` (pinhole and pose), `world/camera/depth`, `world/camera/depth/detections`
(boxes), `world/occupancy` (the map as an image, magma), `world/tracks` (points labelled with
the identity), `world/trails` (line strips), with zones and lines `world/zones` and
`world/lines` (on the floor, labelled with each frame's count and crossings so far), on the
`frame` timeline (and `time` in seconds when the frames have timestamps).
"""

from __future__ import annotations

import numpy as np

INSTALL = 'pip install "dpom-warp[view]"'


def _rerun():
    from .sources import need

    return need("rerun", "output.rerun / --view", package="rerun-sdk", install=INSTALL)


class RerunLog:
    """One run's Rerun recording: to `path` (.rrd), and to a spawned viewer with `spawn`."""

    def __init__(self, path: str | None, spawn: bool = False, name: str = "dpom-warp"):
        rr = _rerun()
        self.rr = rr
        self.rec = rr.RecordingStream(name)
        self.paths = ["world/camera"]  # each camera's entity (a rig's: world/cameras/NAME, set by `camera`)
        self.parts = None  # a rig's geometry.Geometry a camera (`camera`): each camera's own boxes
        if path:
            from pathlib import Path

            Path(path).parent.mkdir(parents=True, exist_ok=True)
            self.rec.save(str(path))
        if spawn:
            self.rec.spawn(connect=not path)

    def camera(self, camera, names: list[str] | None = None, parts: list | None = None) -> None:
        """The posed camera at `world/camera`; a rig's (a list, `names`) at `world/cameras/NAME`,
        each camera's detection boxes from its geometry in `parts` (geometry.RigGeometry.parts)."""
        self.parts = parts
        rr, rec = self.rr, self.rec
        rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self.paths = [f"world/cameras/{n}" for n in names] if names else ["world/camera"]
        for path, cam in zip(self.paths, camera if names else [camera]):
            rec.log(path, rr.Transform3D(translation=cam.centre, mat3x3=cam.R_wc), static=True)
            rec.log(path, rr.Pinhole(resolution=[cam.width, cam.height], focal_length=[cam.fx, cam.fy],
                                     principal_point=[cam.cx, cam.cy]), static=True)

    def frame(self, index: int, timestamp: float | None, depth_m: np.ndarray, dets: list, rho_map: np.ndarray,
              tracks: list | None = None) -> None:
        """One frame: `dets` (detect.Detected), `tracks` dicts of id, xyz, trail (positions)."""
        from .render import colourise

        rr, rec = self.rr, self.rec
        self._at(index, timestamp)
        for path, depth in zip(self.paths, depth_m if len(self.paths) > 1 else [depth_m]):  # a rig's: one a camera
            if depth is not None:
                rec.log(f"{path}/depth", rr.DepthImage(np.asarray(depth, np.float32), meter=1.0))
        top = rho_map.max(axis=0) if rho_map.ndim == 3 else rho_map
        rec.log("world/occupancy", rr.Image(colourise(top[::-1], 0.0, 1.0, "magma")))
        self.tracks(index, timestamp, dets, tracks)

    def tracks(self, index: int, timestamp: float | None, dets: list, tracks: list | None) -> None:
        """Frame `index`'s detection boxes, labelled with the identity of the track on each
        (none without `tracks`), and its tracks and trails: with the frame (`frame`), or once
        a live run's online tracker has committed it, logged again at its time."""
        from .render import track_colour, track_identities

        rr, rec = self.rr, self.rec
        self._at(index, timestamp)
        ident = track_identities(dets, tracks or [])
        labels = [(f"#{ident[i]} " if i in ident else "") + f"{d.rho:.2f}" for i, d in enumerate(dets)]
        # each camera's boxes: a rig's as that camera sees each detection (those in its view)
        for path, g in zip(self.paths, self.parts or [None]):
            seen = [i for i, d in enumerate(dets) if g is None or g.rect_area[d.k] > 0]
            boxes = np.array([dets[i].box if g is None else g.rect[dets[i].k] for i in seen], float).reshape(-1, 4)
            rec.log(f"{path}/depth/detections",
                    rr.Boxes2D(array=boxes, array_format=rr.Box2DFormat.XYXY, labels=[labels[i] for i in seen]))
        if tracks is not None:
            pos = np.array([t["xyz"] for t in tracks], float).reshape(-1, 3)
            colours = [track_colour(t["id"]) for t in tracks]
            rec.log("world/tracks", rr.Points3D(pos, labels=[str(t["id"]) for t in tracks], colors=colours,
                                                radii=0.15))
            rec.log("world/trails", rr.LineStrips3D([np.asarray(t["trail"], float).reshape(-1, 3) for t in tracks],
                                                    colors=colours))

    def zones(self, index: int, timestamp: float | None, overlay: dict) -> None:
        """Frame `index`'s zones and lines on the floor with their labels (zone_tables.ZoneTables'
        overlay: each zone's count, each line's crossings so far)."""
        rr, rec = self.rr, self.rec
        self._at(index, timestamp)
        zones, lines = overlay.get("zones", ()), overlay.get("lines", ())
        if zones:
            strips = [np.column_stack([np.vstack([p, p[:1]]), np.zeros(len(p) + 1)]) for p, _ in zones]
            rec.log("world/zones", rr.LineStrips3D(strips, labels=[label for _, label in zones], colors=[(80, 200, 255)]))
        if lines:
            strips = [np.array([[*a, 0.0], [*b, 0.0]]) for a, b, _ in lines]
            rec.log("world/lines", rr.LineStrips3D(strips, labels=[label for _, _, label in lines],
                                                   colors=[(120, 255, 120)]))

    def _at(self, index: int, timestamp: float | None) -> None:
        self.rec.set_time("frame", sequence=index)
        if timestamp is not None:
            self.rec.set_time("time", duration=float(timestamp))

    def close(self) -> None:
        self.rec.flush()
        self.rec.disconnect()

