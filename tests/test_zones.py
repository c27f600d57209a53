"""Where people go (issue 62): zones, lines and stays worked out by hand, the config's checks, the
files of a rendered run against the truth from its trajectories, `dpom-warp track` counting
other zones, the live stream and the Python API."""

import csv
import json

import numpy as np
import pytest
import yaml

from dpom_warp.cli import main
from dpom_warp.zones import Line, Zone, Zones, inside, meets_rectangle, on_segment, self_crossing, side, steps_through

SQUARE = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 2.0], [0.0, 2.0]])
# an L: the square less its top right quarter (concave at (1, 1))
ELL = np.array([[0.0, 0.0], [2.0, 0.0], [2.0, 1.0], [1.0, 1.0], [1.0, 2.0], [0.0, 2.0]])


def test_inside_counts_the_edges_and_the_vertices():
    pts = [[1.0, 1.0], [0.0, 1.0], [2.0, 2.0], [2.0 + 1e-6, 1.0], [1.0, -1e-6], [0.5, 1.5], [1.5, 1.5], [1.0, 1.5]]
    assert inside(SQUARE, pts).tolist() == [True, True, True, False, False, True, True, True]
    # the L: its notch is outside, its inner corner and the notch's edges inside
    assert inside(ELL, pts).tolist() == [True, True, False, False, False, True, False, True]
    assert inside(SQUARE, np.zeros((0, 2))).tolist() == []


def test_sides_and_steps_through_a_segment_by_hand():
    line = Line("door", np.array([0.0, 0.0]), np.array([0.0, 2.0]))  # pointing +y: its left is -x
    np.testing.assert_allclose(side(line, [[-1.0, 1.0], [0.5, 5.0], [0.0, 3.0]]), [1.0, -0.5, 0.0])
    # a line off the origin, pointing +x: its left is +y, distances from y = 1
    off = Line("bar", np.array([1.0, 1.0]), np.array([3.0, 1.0]))
    np.testing.assert_allclose(side(off, [[2.0, 3.0], [0.0, 0.0], [5.0, 1.0], [-4.0, 1.5]]), [2.0, -1.0, 0.0, 0.5])
    assert steps_through(line, np.array([1.0, 1.0]), np.array([-1.0, 1.0]))  # through the middle
    assert steps_through(line, np.array([1.0, 1.0]), np.array([-1.0, 3.0]))  # through the end (0, 2) exactly
    assert not steps_through(line, np.array([1.0, 1.5]), np.array([-1.0, 3.5]))  # over the line beyond its end
    assert not steps_through(line, np.array([1.0, 1.0]), np.array([0.5, 1.0]))  # not reaching it
    assert steps_through(line, np.array([0.0, 2.0]), np.array([0.0, 3.0]))  # along it, from its end
    assert not steps_through(line, np.array([0.0, 2.5]), np.array([0.0, 3.0]))  # along the line, past its end
    assert steps_through(line, np.array([0.0, -1.0]), np.array([0.0, 3.0]))  # along it, over the whole segment
    assert steps_through(line, np.array([0.0, 1.0]), np.array([-1.0, 1.0]))  # from a point on it
    assert steps_through(line, np.array([1.0, 1.0]), np.array([0.0, 1.0]))  # onto it
    assert on_segment(np.array([[0.25, 0.0], [0.25, 0.01]]), np.array([0.0, 0.0]), np.array([0.5, 0.0])).tolist() == [
        True, False]  # a segment shorter than 1 m
    assert on_segment(np.array([[2.25, 1.0], [2.25, 1.01], [1.5, 1.0], [2.5, 1.0]]), np.array([2.0, 1.0]),
                      np.array([2.5, 1.0])).tolist() == [True, False, False, True]  # one off the origin


def test_a_polygon_that_crosses_itself_is_found():
    assert self_crossing(SQUARE) is None and self_crossing(ELL) is None
    assert self_crossing(np.array([[0.0, 0.0], [2.0, 2.0], [2.0, 0.0], [0.0, 2.0]])) == (0, 2)  # a bow tie
    assert self_crossing(np.array([[0.0, 0.0], [2.0, 0.0], [1.0, 0.0], [1.0, 1.0]])) is not None  # doubling back


def walker(xs, y=1.0, tid=7):
    """One track's committed rows, frame by frame, at x = xs[f]."""
    return [[(tid, (x, y, 0.0), False)] for x in xs]


def crossings_of(frames, hysteresis=0.2, line=None):
    z = Zones([], [line or Line("door", np.array([0.0, 0.0]), np.array([0.0, 2.0]))], hysteresis, fps=10.0)
    out = []
    for f, rows in enumerate(frames):
        out += [(c.frame, c.line, c.track, c.direction) for c in z.update(f, rows).crossings]
    return out


def test_a_crossing_is_dated_at_its_first_frame_on_the_new_side():
    """Right (x > 0) to left: `in`, dated at frame 2 (the first frame at x < 0), though only
    confirmed at frame 3 (beyond the 0.2 m hysteresis); back again: `out` at frame 5."""
    assert crossings_of(walker([0.6, 0.3, -0.1, -0.5, -0.1, 0.05, 0.4])) == [(2, "door", 7, "in"), (5, "door", 7, "out")]


def test_a_track_that_jitters_on_the_line_is_counted_once():
    """Back and forth within the hysteresis: nothing; then well over: one crossing, dated at the
    last time it went over (the frames back on its side forget the earlier steps)."""
    assert crossings_of(walker([0.5, -0.1, 0.1, -0.15, 0.12, -0.05, 0.15])) == []
    assert crossings_of(walker([0.5, -0.1, 0.1, -0.15, 0.1, -0.05, -0.6])) == [(5, "door", 7, "in")]
    # the same jitter with no hysteresis: every step over is a crossing
    assert len(crossings_of(walker([0.5, -0.1, 0.1, -0.15]), hysteresis=0.0)) == 3


def test_a_frame_on_the_line_is_on_neither_side():
    """A track that stops exactly on the line (x = 0) has not crossed yet: the crossing is dated
    at its first frame past it, either way; a track that touches the line and goes back has not
    crossed. A track exactly `hysteresis` from the line (0.2 m) is not beyond it: more is."""
    assert crossings_of(walker([0.5, 0.0, -0.5])) == [(2, "door", 7, "in")]
    assert crossings_of(walker([-0.5, 0.0, 0.5])) == [(2, "door", 7, "out")]
    assert crossings_of(walker([0.5, 0.0, 0.0, 0.5])) == []
    assert crossings_of(walker([-0.5, 0.1, 0.0, 0.5])) == [(1, "door", 7, "out")]  # over, onto it, on
    assert crossings_of(walker([0.5, -0.2, -0.2])) == []
    assert crossings_of(walker([0.5, -0.2, -0.2 - 1e-6])) == [(1, "door", 7, "in")]


def test_crossings_beyond_the_segment_and_through_its_end():
    """Over the line beyond the segment's end: none; through the end point exactly: counted. A
    track first seen within the hysteresis has no side yet: its first crossing needs one."""
    assert crossings_of(walker([0.6, -0.6], y=2.5)) == []
    assert crossings_of([[(1, (0.5, 1.5, 0.0), False)], [(1, (-0.5, 2.5, 0.0), False)]]) == [(1, "door", 1, "in")]
    assert crossings_of(walker([0.1, -0.5])) == []


def test_counts_and_stays_by_hand():
    """Two tracks and the square zone at 4 frames a second: track 1 inside frames 0-2 (0.75 s:
    from frame 0's time to frame 3's), track 2 inside from frame 1 to the end (3 frames + one
    more frame's time: 0.75 s at finish); a track that ends inside ends its stay."""
    z = Zones([Zone("square", SQUARE)], [], 0.1, fps=4.0)
    rows = [[(1, (1.0, 1.0, 0), False), (2, (3.0, 1.0, 0), False)],
            [(1, (1.5, 1.0, 0), True), (2, (2.0, 1.0, 0), False)],  # 2 on the edge: inside
            [(1, (0.5, 0.5, 0), False), (2, (1.0, 1.0, 0), False)],
            [(1, (2.5, 0.5, 0), False), (2, (1.0, 1.5, 0), False)]]
    counts = [z.update(f, r).counts["square"] for f, r in enumerate(rows)]
    assert counts == [1, 2, 2, 1]
    stays = [(s.track, s.zone, s.enter_frame, s.exit_frame, s.seconds) for s in z.finish()]
    assert stays == [(1, "square", 0, 2, 0.75), (2, "square", 1, 3, 0.75)]
    timed = Zones([Zone("square", SQUARE)], [], 0.1, fps=4.0)
    timed.update(0, [(5, (1.0, 1.0, 0), False)], timestamp=10.0)
    timed.update(1, [(5, (1.0, 1.0, 0), False)], timestamp=10.4)
    timed.update(2, [], timestamp=11.5)  # the track ended
    assert [(s.enter_frame, s.exit_frame, s.seconds) for s in timed.stays] == [(0, 1, pytest.approx(1.5))]
    with pytest.raises(ValueError, match="frames must come in increasing order"):
        timed.update(2, [])


def test_what_meets_the_grid_by_hand():
    """The check behind "a zone or line wholly outside the grid" (the rectangle x 0 to 2, y 0 to
    2): a vertex inside, the grid inside the zone, or only an edge across it meet it; a zone
    beside it at the grid's heights, or a line beside it, do not."""
    rect = (0.0, 2.0, 0.0, 2.0)
    assert meets_rectangle(np.array([[1.0, 1.0], [5.0, 1.0], [5.0, 5.0]]), rect, True)  # a vertex in it
    assert meets_rectangle(np.array([[-1.0, -1.0], [3.0, -1.0], [3.0, 3.0], [-1.0, 3.0]]), rect, True)  # around it
    band = np.array([[3.0, 0.9], [3.0, 1.1], [-1.0, 1.1], [-1.0, 0.9]])  # across it, its first edge outside
    assert meets_rectangle(band, rect, True)
    assert not meets_rectangle(np.array([[-3.0, 0.5], [-2.0, 0.5], [-2.0, 1.0]]), rect, True)  # left of it
    assert meets_rectangle(np.array([[-1.0, 1.0], [3.0, 1.5]]), rect, False)  # a line across it
    assert not meets_rectangle(np.array([[-1.0, 1.0], [-0.5, 3.0]]), rect, False)  # a line beside it


def small_zoned(tmp_path, frames=20, **changes):
    """test_cli's small config on a 0.1 m grid (cell centres at +-0.05 m about x = 0), 20 frames
    of 3 people, a zone over the left half of the grid (a rectangle: its truth is x <= 0) and a
    line along x = 0 across the whole grid (its truth: x changes sign)."""
    from test_cli import small_config

    path = small_config(tmp_path, frames=frames)
    cfg = yaml.safe_load(path.read_text())
    cfg["grid"].update(x=[-2.5, 2.5, 0.1], y=[1.0, 6.5, 0.1])
    cfg["zones"] = [{"name": "left", "polygon": [[-3.0, 0.5], [0.0, 0.5], [0.0, 7.0], [-3.0, 7.0]]}]
    cfg["lines"] = [{"name": "middle", "from": [0.0, 0.5], "to": [0.0, 7.0]}]
    cfg["synthetic"]["step_m"] = 0.3
    cfg.update(changes)
    path.write_text(yaml.safe_dump(cfg))
    return path


def read_rows(path):
    return list(csv.DictReader(open(path)))


def test_a_rendered_run_counts_as_its_trajectories_do(tmp_path):
    """zones.csv (a row a frame and zone) against the truth computed from the rendered people's
    positions by hand (x <= 0), crossings.csv against the truth's own crossings of x = 0 (a
    person's x changing sign from one frame to the next; matched: same direction within 3
    frames), beside the naive
    count of raw detections in the zone; summary.json's totals are the files'; the pictures are
    there. Targets: counts exact in >= 95 % of rows, crossings precision and recall >= 0.9."""
    from pictures import assert_picture

    path = small_zoned(tmp_path)
    assert main(["run", str(path), "--no-progress", "--set", f"output.rerun={tmp_path / 'run.rrd'}"]) == 0
    out = tmp_path / "out"
    truth = json.loads((tmp_path / "scene" / "trajectories.json").read_text())  # every person, hidden or not
    seen = json.loads((tmp_path / "scene" / "ground_truth.json").read_text())
    assert all(len(f["objects"]) == 3 for f in truth)  # the renderer's trajectories: each person every frame
    for f, g in zip(truth, seen):  # the ground truth: those seen, at the same places
        at = {o["id"]: (o["x"], o["y"]) for o in f["objects"]}
        assert f["frame"] == g["frame"] and all(at[o["id"]] == (o["x"], o["y"]) for o in g["objects"])
    rows = read_rows(out / "zones.csv")
    assert [r["frame"] for r in rows] == [f["frame"] for f in truth] and {r["zone"] for r in rows} == {"left"}

    def in_left(o):
        return o["x"] <= 0.0

    want = {f["frame"]: sum(in_left(o) for o in f["objects"]) for f in truth}
    exact = np.mean([int(r["count"]) == want[r["frame"]] for r in rows])
    dets = {}
    for r in read_rows(out / "detections.csv"):
        dets[r["frame"]] = dets.get(r["frame"], 0) + in_left({"x": float(r["x"]), "y": float(r["y"])})
    naive = np.mean([dets.get(f, 0) == n for f, n in want.items()])
    print(f"zone counts exact: tracks {exact:.3f}, raw detections {naive:.3f}")
    assert exact >= 0.95
    # the truth's crossings: a person's x changes sign between consecutive frames (the line spans the grid)
    where, last = {}, {}
    true_cross = []
    for f, frame in enumerate(truth):
        for o in frame["objects"]:
            if where.get(o["id"]) == f - 1 and (last[o["id"]] > 0) != (o["x"] > 0):
                true_cross.append((f, "in" if o["x"] < 0 else "out"))  # in: to the left of +y, x < 0
            where[o["id"]], last[o["id"]] = f, o["x"]
    got = [(int(r["frame"][:4]), r["direction"]) for r in read_rows(out / "crossings.csv")]
    assert len(true_cross) >= 2  # the scene has crossings to find
    unmatched = list(got)
    found = 0
    for f, d in true_cross:
        m = next((g for g in unmatched if g[1] == d and abs(g[0] - f) <= 3), None)
        if m is not None:
            unmatched.remove(m)
            found += 1
    precision, recall = found / max(len(got), 1), found / len(true_cross)
    print(f"crossings: {len(true_cross)} true, {len(got)} found, precision {precision:.2f}, recall {recall:.2f}")
    assert precision >= 0.9 and recall >= 0.9
    summary = json.loads((out / "summary.json").read_text())
    counts = [int(r["count"]) for r in rows]
    assert summary["zones"]["left"]["peak"] == max(counts) and summary["zones"]["left"]["mean"] == pytest.approx(np.mean(counts))
    assert summary["lines"]["middle"] == {d: sum(g[1] == d for g in got) for d in ("in", "out")}
    stays = read_rows(out / "dwell.csv")
    assert stays and all(float(s["seconds"]) > 0 for s in stays)
    assert summary["zones"]["left"]["stays"] == len(stays)
    assert_picture(out / "heatmap.png") is not None and assert_picture(out / "counts.png", plot=True) is not None
    # every frame's picture shows the zone's outline and the line (their colours, on the map), and
    # the Rerun log has them each frame
    from dpom_warp.render import LINE_INK, ZONE_INK

    rgb = assert_picture(out / "images" / "0010.png")
    for ink in (ZONE_INK, LINE_INK):
        assert np.all(rgb == ink, axis=-1).sum() > 200, ink
    from rerun.chunk import RrdReader

    rows = {}
    for chunk in RrdReader(str(tmp_path / "run.rrd")).stream():
        rows[chunk.entity_path] = rows.get(chunk.entity_path, 0) + chunk.num_rows
    assert rows["/world/zones"] == rows["/world/lines"] == len(truth)


def test_track_counts_other_zones_without_inferring(tmp_path, capsys):
    """`dpom-warp track RUN --zones FILE` counts the file's zones over the run's tracks (the maps
    untouched; the zone half a metre wider than the grid: a track at a head may stand outside it); `--set zones=[] --set lines=[]` removes the files; a bad zone is one line."""
    path = small_zoned(tmp_path, frames=8)
    assert main(["run", str(path), "--no-progress"]) == 0
    out = tmp_path / "out"
    maps = (out / "maps" / "0003.npy").read_bytes()
    zones = tmp_path / "zones.yaml"
    zones.write_text(yaml.safe_dump({"zones": [{"name": "all", "polygon": [[-3.0, 0.5], [3.0, 0.5], [3.0, 7.0],
                                                                                   [-3.0, 7.0]]}]}))
    assert main(["track", str(out), "--zones", str(zones)]) == 0
    rows = read_rows(out / "zones.csv")
    tracks = read_rows(out / "tracks.csv")
    per_frame = {}
    for t in tracks:
        per_frame[t["frame"]] = per_frame.get(t["frame"], 0) + 1
    assert {r["zone"] for r in rows} == {"all"} and all(int(r["count"]) == per_frame.get(r["frame"], 0) for r in rows)
    assert read_rows(out / "crossings.csv") == [] and (out / "maps" / "0003.npy").read_bytes() == maps
    assert main(["track", str(out), "--set", "zones=[]", "--set", "lines=[]"]) == 0
    assert not (out / "zones.csv").exists() and "zones" not in json.loads((out / "summary.json").read_text())
    assert main(["track", str(out), "--set", "zones=[{name: a, polygon: [[0, 1], [1, 1]]}]"]) == 2
    assert "zones[0].polygon: expected at least 3 points [x, y], found 2" in capsys.readouterr().err


@pytest.mark.parametrize("change, message", [
    ({"zones": [{"name": "a", "polygon": [[0, 1], [1, 1]]}]}, r"zones\[0\]\.polygon: expected at least 3 points"),
    ({"zones": [{"name": "a", "polygon": [[0, 1], [1, 2], [1, 1], [0, 2]]}]},
     r"zones\[0\]\.polygon: expected a polygon that does not cross itself, found its edges 0 and 2 meeting"),
    ({"lines": [{"name": "a", "from": [0, 2], "to": [0, 2]}]}, r"lines\[0\]: expected a line of some length"),
    ({"lines": [{"name": "a", "from": [9, 2], "to": [9, 3]}]},
     r"lines\[0\]: expected a line over the grid \(x -2\.5 to 2\.5 m, y 1 to 6\.5 m\), found it wholly outside"),
    ({"zones": [{"name": "a", "polygon": [[20, 20], [21, 20], [21, 21]]}]}, r"zones\[0\]: expected a zone over the grid"),
    ({"lines": [{"name": "a", "from": [0, 2], "to": [0, 3]}, {"name": "a", "from": [1, 2], "to": [1, 3]}]},
     r"lines\[1\]\.name: expected a name unlike the other lines', found 'a' again \(lines\[0\]\)"),
    ({"lines": [{"name": "a", "form": [0, 2], "to": [0, 3]}]}, r"lines\[0\]\.form: unknown key \(expected one of name, from, to\)"),
    ({"tracking": {"method": "off"}}, r"tracking\.method: zones and lines count the tracks"),
    ({"counting": {"hysteresis": -0.1}}, r"counting\.hysteresis: expected a value >= 0, found -0\.1"),
])
def test_bad_zones_and_lines_are_one_line_errors(tmp_path, capsys, change, message):
    import re

    path = small_zoned(tmp_path, **change)
    assert main(["run", str(path), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert re.search(message, err) and err.count("\n") == 1 and not (tmp_path / "out").exists()


def test_the_live_stream_writes_as_it_commits(tmp_path):
    """--play with --events: one JSON line per committed frame, in order, with the counts that
    zones.csv holds for that frame (written as it goes), and the crossings crossings.csv holds."""
    path = small_zoned(tmp_path, frames=8)
    events = tmp_path / "events.jsonl"
    assert main(["run", str(path), "--no-progress", "--play", "--events", str(events), "--output",
                 str(tmp_path / "live")]) == 0
    lines = [json.loads(x) for x in events.read_text().splitlines()]
    rows = read_rows(tmp_path / "live" / "zones.csv")
    assert [e["index"] for e in lines] == list(range(len(lines))) and len(lines) == len(rows) >= 1
    assert [(e["frame"], e["counts"]["left"]) for e in lines] == [(r["frame"], int(r["count"])) for r in rows]
    crossed = [c for e in lines for c in e["crossings"]]
    assert [(c["frame"], c["line"], str(c["track"]), c["direction"]) for c in crossed] == [
        (r["frame"], r["line"], r["track"], r["direction"]) for r in read_rows(tmp_path / "live" / "crossings.csv")]


def test_the_api_counts_an_online_tracker_loop(tmp_path):
    """Zones.from_config(detector.config).update(i, committed tracks) over the Detector's online
    tracker gives the counts of each committed frame (the tracks inside the zone, by hand)."""
    import dpom_warp
    from dpom_warp import Detector
    from dpom_warp.io import read_depth

    path = small_zoned(tmp_path, frames=6, counting={"hysteresis": 0.25})
    cfg = yaml.safe_load(path.read_text())
    cfg["input"]["fps"] = 4.0
    path.write_text(yaml.safe_dump(cfg))
    det = Detector.from_config(path)
    zones = dpom_warp.Zones.from_config(det.config)
    assert (zones.hysteresis, zones.fps) == (0.25, 4.0)  # the config's, not the defaults (0.1 m, 15/s)
    online = det.online_tracker()
    frames = sorted((tmp_path / "scene" / "frames").glob("*.png"))
    got = []

    def count(committed):
        for i, rows in committed:
            events = zones.update(i, rows)
            assert events.frame == i
            got.append((events.counts["left"], sum(p[0] <= 0 for _, p, _ in rows)))

    for f in frames:
        count(online.push(det.detect(read_depth(f, 0.001, (106, 128)))))
    count(online.finish())
    assert len(got) == len(frames) and all(a == b for a, b in got) and any(a > 0 for a, _ in got)


def test_many_zones_at_once_agree_with_matplotlib():
    """Regions (every zone's edges in one array: the bookkeeping's fast path) gives what
    matplotlib's Path plus the edges gives (inside) for an L, a square and a random 7-gon (which
    may cross itself: both by the even-odd rule), on 2000 random points and the vertices."""
    from dpom_warp.zones import Regions

    rng = np.random.default_rng(0)
    polygons = [ELL, SQUARE, rng.uniform(-1, 3, (7, 2))]
    points = np.vstack([rng.uniform(-0.5, 2.5, (2000, 2)), ELL, SQUARE, [[1.0, 1.5], [1.5, 1.0], [0.0, 1.0]]])
    got = Regions(polygons).inside(points)
    for polygon, row in zip(polygons, got):
        np.testing.assert_array_equal(row, inside(polygon, points))
    assert got[0].sum() > 300 and not got[0].all()
    # by hand: points level with a diamond's side vertices (each vertex met once, by the even-odd
    # count's half-open edges) and the middles of a 0.5 m square's edges (shorter than 1 m)
    diamond = np.array([[0.0, 1.0], [1.0, 0.0], [2.0, 1.0], [1.0, 2.0]])
    small = np.array([[0.0, 0.0], [0.5, 0.0], [0.5, 0.5], [0.0, 0.5]])
    level = [[1.0, 1.0], [0.5, 1.0], [1.9, 1.0], [2.5, 1.0], [-0.5, 1.0], [2.0, 1.0]]
    middles = [[0.25, 0.0], [0.5, 0.25], [0.25, 0.5], [0.0, 0.25], [0.25, 0.5 + 1e-6]]
    got = Regions([diamond, small]).inside(np.array(level + middles, float))
    assert got[0].tolist() == [True, True, True, False, False, True] + [False] * 5
    assert got[1].tolist() == [False] * 6 + [True, True, True, True, False]
    for polygon, row in zip((diamond, small), got):
        np.testing.assert_array_equal(row, inside(polygon, level + middles))
