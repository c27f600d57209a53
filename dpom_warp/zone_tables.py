"""The outputs of zones and lines (issue 62's contract), written by the `ZoneTables` writer from each
frame's committed tracks (zones.Zones):

- zones.csv `frame,zone,count`: every frame and every zone, the tracks inside it;
- crossings.csv `frame,line,track,direction`: each crossing, at the first frame on the new side;
- dwell.csv `track,zone,enter_frame,exit_frame,seconds`: each stay, in the order stays end;
- heatmap.png: where people stood over the run (seconds per cell, the zones and lines drawn);
  counts.png: each zone's count and each line's crossings (in, out; cumulative) over the frames;
- summary.json's `zones` (each zone's peak and mean count and mean stay) and `lines` (each
  line's in and out totals);
- with counting.events (or --events): one JSON line per committed frame, its counts and the
  crossings confirmed at it, for a dashboard or a robot (`-`: standard output).

A recorded run writes the CSV files once its tracks are final, each atomically; a live run
appends each committed frame's rows as it goes and flushes them (and the events), so a reader
sees every frame committed so far. Frames are named as in detections.csv."""

from __future__ import annotations

import json
import sys

import numpy as np

from .io import write_text_atomic
from .zones import Zones

FILES = ("zones.csv", "crossings.csv", "dwell.csv", "heatmap.png", "counts.png")
HEADERS = {"zones.csv": "frame,zone,count", "crossings.csv": "frame,line,track,direction",
           "dwell.csv": "track,zone,enter_frame,exit_frame,seconds"}


class ZoneTables:
    """The zones' and lines' outputs of a run (module doc), a writer (writers.Writer's events);
    with neither in the config, an earlier run's are removed (`dpom-warp track --set zones=[]`)."""

    wants_tracked = True
    parallel = False

    def __init__(self, run):
        self.run = run
        cfg = run.cfg
        self.on = bool(cfg.zones or cfg.lines)
        self.zones = Zones.from_config(cfg) if self.on else None
        self.names: list[str] = []  # frame names by index
        self.rows = {name: [] for name in HEADERS}
        self.counts: list[dict] = []
        self.totals = {x.name: {"in": 0, "out": 0} for x in cfg.lines}
        self.per_frame_crossings: list[dict] = []
        g = cfg.grid
        self.heat = np.zeros(g.shape[-2:])
        self.stream = cfg.live  # a live run: the rows appended and flushed per committed frame
        self.files = {}
        self.events = None
        target = getattr(cfg.counting, "events", None) if cfg.counting is not None else None
        if self.on and target:
            self.events = sys.stdout if target == "-" else open(target, "w", buffering=1)

    def prefetch(self, done) -> None:
        pass

    def frame(self, done) -> None:
        pass

    def tracked(self, done, shown):
        if not self.on or shown is None:  # untracked (one frame): nothing to count
            return
        while len(self.names) <= done.index:
            self.names.append("")
        self.names[done.index] = done.name
        events = self.zones.update(done.index, shown, done.timestamp)
        closed = self.zones.stays[len(self.rows["dwell.csv"]):]
        rows = {"zones.csv": [f"{done.name},{z},{n}" for z, n in events.counts.items()],
                "crossings.csv": [f"{self.names[c.frame]},{c.line},{c.track},{c.direction}" for c in events.crossings],
                "dwell.csv": [self._stay(s) for s in closed]}
        for c in events.crossings:
            self.totals[c.line][c.direction] += 1
        done.zone_overlay = {  # what the frame's picture shows (writers.Pictures, after this writer)
            "zones": [(z.polygon, f"{z.name}: {events.counts[z.name]}") for z in self.zones.zones],
            "lines": [(x.start, x.end, f"{x.name}: {self.totals[x.name]['in']} in, {self.totals[x.name]['out']} out")
                      for x in self.zones.lines]}
        self.counts.append(events.counts)
        self.per_frame_crossings.append({x.name: dict(self.totals[x.name]) for x in self.zones.lines})
        g = self.run.cfg.grid
        for t in shown:
            i = int(np.floor((t["xyz"][1] - g.y[0]) / g.y[2]))
            j = int(np.floor((t["xyz"][0] - g.x[0]) / g.x[2]))
            if 0 <= i < self.heat.shape[0] and 0 <= j < self.heat.shape[1]:
                self.heat[i, j] += 1
        for name, new in rows.items():
            self.rows[name] += new
            if self.stream:
                self._append(name, new)
        if self.events is not None:
            self.events.write(json.dumps({
                "frame": done.name, "index": done.index, "timestamp": done.timestamp, "counts": events.counts,
                "crossings": [{"frame": self.names[c.frame], "line": c.line, "track": c.track,
                               "direction": c.direction} for c in events.crossings]}) + "\n")
            self.events.flush()

    def _stay(self, s) -> str:
        return f"{s.track},{s.zone},{self.names[s.enter_frame]},{self.names[s.exit_frame]},{s.seconds:.3f}"

    def _append(self, name: str, rows: list[str]) -> None:
        if name not in self.files:
            self.files[name] = open(self.run.out / name, "w")
            self.files[name].write(HEADERS[name] + "\n")
        for row in rows:
            self.files[name].write(row + "\n")
        self.files[name].flush()

    def finish(self, end):
        out = self.run.out
        if not self.on:
            for name in FILES:
                (out / name).unlink(missing_ok=True)
            if end.summary is not None:
                end.summary.pop("zones", None)
                end.summary.pop("lines", None)
            return
        closed = len(self.rows["dwell.csv"])
        stays = self.zones.finish() if self.zones._frame is not None else []
        self.rows["dwell.csv"] += [self._stay(s) for s in stays[closed:]]
        for name in HEADERS:
            if self.stream:
                self._append(name, self.rows["dwell.csv"][closed:] if name == "dwell.csv" else [])
            else:
                write_text_atomic(out / name, "\n".join([HEADERS[name], *self.rows[name]]) + "\n")
        self.close()
        fps = self.zones.fps
        if end.summary is not None:
            end.summary["zones"] = {z.name: {
                "peak": max((c[z.name] for c in self.counts), default=0),
                "mean": float(np.mean([c[z.name] for c in self.counts])) if self.counts else 0.0,
                "stays": sum(s.zone == z.name for s in stays),
                "mean_dwell_s": (float(np.mean([s.seconds for s in stays if s.zone == z.name]))
                                 if any(s.zone == z.name for s in stays) else None)} for z in self.zones.zones}
            end.summary["lines"] = {x.name: dict(self.totals[x.name]) for x in self.zones.lines}
        if self.counts:
            zone_figures(self.run.cfg, self.zones, self.heat / fps, self.counts, self.per_frame_crossings,
                         out / "heatmap.png", out / "counts.png")

    def close(self):
        for f in self.files.values():
            f.close()
        self.files = {}
        if self.events is not None and self.events is not sys.stdout:
            self.events.close()
        self.events = None


def zone_figures(cfg, zones: Zones, seconds: np.ndarray, counts: list[dict], crossings: list[dict],
                 heat_path, counts_path) -> None:
    """heatmap.png (seconds people stood on each cell, the zones outlined, the lines drawn with
    their in/out totals) and counts.png (each zone's count per frame; each line's cumulative
    crossings in and out)."""
    from .plots import save_figure  # (first: it sets matplotlib's Agg backend)

    import matplotlib.pyplot as plt

    g = cfg.grid
    extent = (g.x[0], g.x[0] + seconds.shape[1] * g.x[2], g.y[0], g.y[0] + seconds.shape[0] * g.y[2])
    fig, ax = plt.subplots(figsize=(6, 6 * (extent[3] - extent[2]) / max(extent[1] - extent[0], 1e-9) + 0.6), dpi=90)
    im = ax.imshow(seconds, origin="lower", extent=extent, cmap="magma", interpolation="nearest")
    fig.colorbar(im, ax=ax, label="seconds stood there")
    for z in zones.zones:
        p = np.vstack([z.polygon, z.polygon[:1]])
        ax.plot(p[:, 0], p[:, 1], color="tab:cyan", lw=2)
        ax.text(*z.polygon.mean(0), z.name, color="tab:cyan", ha="center", va="center", fontsize=9)
    for x in zones.lines:
        ax.annotate("", xy=x.end, xytext=x.start, arrowprops={"arrowstyle": "->", "color": "tab:green", "lw": 2})
        last = crossings[-1][x.name] if crossings else {"in": 0, "out": 0}
        ax.text(*(x.start + x.end) / 2, f"{x.name}: {last['in']} in, {last['out']} out", color="tab:green",
                fontsize=9, ha="center", va="bottom")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("where people stood")
    save_figure(fig, heat_path)
    fig, axes = plt.subplots(2, 1, figsize=(8, 6), dpi=90, sharex=True)
    frames = np.arange(len(counts))
    for z in zones.zones:
        axes[0].step(frames, [c[z.name] for c in counts], where="post", label=z.name)
    axes[0].set_ylabel("people in the zone")
    for x in zones.lines:
        line, = axes[1].step(frames, [c[x.name]["in"] for c in crossings], where="post", label=f"{x.name} in")
        axes[1].step(frames, [c[x.name]["out"] for c in crossings], where="post", ls="--", color=line.get_color(),
                     label=f"{x.name} out")
    axes[1].set_ylabel("crossings so far")
    axes[1].set_xlabel("frame")
    for ax in axes:
        ax.grid(alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=8, loc="upper left")
    save_figure(fig, counts_path)
