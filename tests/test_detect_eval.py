"""Detections from maps and CLEAR scores, on hand-computed cases."""

import numpy as np
import pytest

from dpom_warp.loading import load_config
from dpom_warp.detect import detect, local_maxima
from dpom_warp.geometry import build_geometry
from paths import ROOT
from dpom_warp.evaluate import match, score_frames


def grid_locations(ny, nx, step=0.1):
    yy, xx = np.meshgrid(np.arange(ny) * step, np.arange(nx) * step, indexing="ij")
    return np.stack([xx.ravel(), yy.ravel(), np.zeros(ny * nx)], 1)


def test_local_maxima_and_nms():
    m = np.zeros((5, 8))
    m[1, 1] = 0.9
    m[1, 2] = 0.8  # neighbour of a stronger cell: not a maximum
    m[1, 4] = 0.7  # a maximum 0.3 m from the strongest: suppressed by a 0.4 m radius
    m[3, 7] = 0.6
    m[4, 0] = 0.3  # below threshold
    assert local_maxima(m)[1, 1] and not local_maxima(m)[1, 2] and local_maxima(m)[1, 4]
    locs = grid_locations(5, 8)
    rect = np.tile([0, 0, 1, 1], (40, 1))
    dets = detect(m, locs, rect, threshold=0.5, nms_radius=0.4)
    assert [(d.k, round(d.rho, 2)) for d in dets] == [(1 * 8 + 1, 0.9), (3 * 8 + 7, 0.6)]
    assert dets[0].x == pytest.approx(0.1) and dets[0].y == pytest.approx(0.1)
    assert len(detect(m, locs, rect, threshold=0.5, nms_radius=0.2)) == 3


def test_cells_a_radius_apart_are_not_closer_than_it_whatever_the_rounding():
    """Two maxima 4 cells of 0.1 m apart are 0.4 m apart: not closer than a 0.4 m suppression
    radius, both kept, wherever the grid starts (at x = 0.3 and 0.7 they are 0.39999999999999997
    m apart in floating point, at 0.1 and 0.5 0.4 exactly; the suppression went by those
    digits); 3 cells apart, the weaker goes. The tracker's peaks and the exclusion prior's
    neighbour lists do the same."""
    from dpom_warp.geometry import neighbour_lists
    from dpom_warp.tracking import Cells, peaks

    rect = np.tile([0, 0, 1, 1], (8, 1))
    rounded = []  # the grids where 4 cells come out closer than 0.4 m in floating point
    for x0 in (0.0, 0.2, 0.3, 0.6):
        locs = np.stack([x0 + 0.1 * np.arange(8), np.zeros(8), np.zeros(8)], 1)
        rounded += [x0] if np.linalg.norm(locs[5] - locs[1]) < 0.4 else []
        for gap, both in ((4, True), (3, False)):
            m = np.zeros((1, 8))
            m[0, 1], m[0, 1 + gap] = 0.9, 0.8
            got = [d.k for d in detect(m, locs, rect, threshold=0.5, nms_radius=0.4)]
            assert got == ([1, 1 + gap] if both else [1]), (x0, gap, got)
            cells = Cells(locs, 0.1, np.zeros(8, bool), 0.4)
            assert list(peaks(m, cells, 0.5)) == ([1, 1 + gap] if both else [1]), (x0, gap)
        start, nbrs = neighbour_lists(locs, 0.4)  # 1, 2 and 3 cells away; 4 is not closer
        assert [list(nbrs[start[k]:start[k + 1]]) for k in (0, 4)] == [[1, 2, 3], [1, 2, 3, 5, 6, 7]], x0
    assert rounded, "no grid here puts 4 cells under 0.4 m by rounding: the case this test is about"


def test_match_prefers_global_assignment():
    # greedy nearest would pair det 0 with gt 0 (0.1 m) and leave gt 1 unmatched at 0.5 gate
    det = np.array([[0.0, 0.0], [0.45, 0.0]])
    gt = np.array([[0.1, 0.0], [-0.3, 0.0]])
    pairs = sorted(match(det, gt, 0.5))
    assert pairs == [(0, 1), (1, 0)]


def test_scores_hand_computed():
    truth = {
        "a.png": [{"x": 0, "y": 0, "visibility": 1.0}, {"x": 2, "y": 0, "visibility": 0.05}],
        "b.png": [{"x": 1, "y": 1, "visibility": 0.9}],
        "c.png": [],
    }
    dets = {"a.png": np.array([[0.1, 0.0]]),  # 1 TP, hidden person missed
            "b.png": np.array([[1.0, 1.3], [5.0, 5.0]]),  # TP at 0.3 m, 1 FP
            "c.png": np.array([[0.0, 0.0]])}  # FP in an empty frame
    s = score_frames(dets, truth, max_distance=0.5, hidden_visibility=0.1, camera_xy=(0.0, -1.0))
    assert (s["n_gt"], s["tp"], s["fp"], s["fn"]) == (3, 2, 2, 1)
    assert s["moda"] == pytest.approx(1 - 3 / 3)
    assert s["precision"] == pytest.approx(0.5) and s["recall"] == pytest.approx(2 / 3)
    assert s["mean_error_m"] == pytest.approx((0.1 + 0.3) / 2)
    # along the line of sight from (0, -1): hypot(0.1, 1) - 1 and hypot(1, 2.3) - hypot(1, 2)
    want = (np.hypot(0.1, 1) - 1 + np.hypot(1, 2.3) - np.hypot(1, 2)) / 2
    assert s["mean_range_error_m"] == pytest.approx(want)
    assert s["n_gt_visible"] == 2 and s["moda_visible"] == pytest.approx(1 - 2 / 2)
    empty = score_frames({}, {"x.png": []}, 0.5)
    assert empty["n_gt"] == 0 and np.isnan(empty["moda"])


def test_saturated_cells_tie_to_the_middle_of_their_blob_and_float32_is_the_map():
    """Two adjacent cells at rho* 1 (float32, as maps are written): the one with more
    occupancy around it is the detection whatever its index; digits below float32 do not
    reorder them, so re-detecting a written map gives the run's detections."""
    ys, xs = np.mgrid[0:5, 0:6]
    locations = np.stack([xs.ravel() * 0.1, ys.ravel() * 0.1, np.zeros(30)], 1)
    rect = np.zeros((30, 4), int)
    for left_first in (True, False):
        m = np.zeros((5, 6))
        m[2, 2] = m[2, 3] = 1.0 - (1e-12 if left_first else 0.0)  # the left one weaker in float64 digits
        m[2, 3] = 1.0
        m[1, 4 if left_first else 1] = 0.8  # beside the right (or the left) one
        got = detect(m, locations, rect, 0.5, 0.4)
        assert len(got) == 1 and got[0].k == (2 * 6 + 3 if left_first else 2 * 6 + 2)
        assert got == detect(m.astype(np.float32), locations, rect, 0.5, 0.4)


def test_a_detection_mostly_outside_the_image_beside_one_in_view_is_dropped():
    """detection.edge_radius: a cell whose silhouette lies mostly outside the image (view part
    under edge_view) within the radius of an at least as strong detection in view is dropped;
    in view of it is only the edge of the person found there. Two cells both mostly outside,
    farther apart, a cell in view beside one outside, or a stronger one outside, stay."""
    locs = grid_locations(1, 12)
    rect = np.tile([0, 0, 1, 1], (12, 1))
    m = np.zeros((1, 12))
    m[0, 0], m[0, 4], m[0, 10] = 0.9, 1.0, 0.8  # 0.4 m apart, then 0.6 m
    view = np.ones(12)
    view[0] = 0.2  # mostly outside the image
    plain = detect(m, locs, rect, 0.5, 0.35)
    assert [d.k for d in plain] == [4, 0, 10]
    assert [d.k for d in detect(m, locs, rect, 0.5, 0.35, view, edge_radius=0.45)] == [4, 10]
    assert [d.k for d in detect(m, locs, rect, 0.5, 0.35, view, edge_radius=0.35)] == [4, 0, 10]
    assert [d.k for d in detect(m, locs, rect, 0.5, 0.35, view, edge_radius=0.45, edge_view=0.1)] == [4, 0, 10]
    view[4] = 0.4  # both mostly outside: neither judges the other
    assert [d.k for d in detect(m, locs, rect, 0.5, 0.35, view, edge_radius=0.45)] == [4, 0, 10]
    view[4], view[10] = 1.0, 0.3  # 0.6 m from the one in view: a person of its own
    assert [d.k for d in detect(m, locs, rect, 0.5, 0.35, view, edge_radius=0.45)] == [4, 10]
    m[0, 0] = 1.0  # as strong as the one in view: dropped
    assert [d.k for d in detect(m, locs, rect, 0.5, 0.35, view, edge_radius=0.45)] == [4, 10]
    m[0, 4] = 0.7  # weaker: someone at the edge beside a weak cell stays
    assert [d.k for d in detect(m, locs, rect, 0.5, 0.35, view, edge_radius=0.45)] == [0, 10, 4]


def test_a_rigs_cell_cut_by_one_image_and_hidden_behind_a_detection_in_the_others_is_dropped():
    """The edge rule in a rig (detect.CameraViews): cells j (x = 0) and k (x = 0.4 m), k weaker.
    Camera A (at x = -3) sees k behind j, j's rectangle covering all of k's; camera B (at
    x = 3) has k cut by its image's edge (0.2 of it in view). What any camera sees of k is the
    edge of j: k goes (the largest share in view over the cameras, 1.0 in A, kept it). k stays
    where A sees it beside j (rectangles apart), where B does not see it at all (then k is a
    person hidden behind j, as one camera's would be), and with camera A alone."""
    from dpom_warp.detect import CameraViews

    locs = np.array([[0.1 * i, 3.0, 0.0] for i in range(5)])
    m = np.array([[1.0, 0.0, 0.0, 0.0, 0.9]])
    box = np.tile([0, 0, 1, 1], (5, 1))
    centre = np.array([[-3.0, 3.0, 2.0], [3.0, 3.0, 2.0]])
    rect = np.zeros((2, 5, 4), np.int64)
    rect[0, 0], rect[0, 4] = [10, 10, 29, 59], [12, 12, 27, 52]  # A: j in front of k, covering it
    rect[1, 0], rect[1, 4] = [5, 0, 30, 49], [0, 0, 9, 49]  # B: k at the image's left edge
    view = np.ones((2, 5))
    view[1, 4] = 0.2

    def found(rects, views, centres=centre):
        area = (rects[..., 2] - rects[..., 0] + 1).clip(0) * (rects[..., 3] - rects[..., 1] + 1).clip(0)
        cams = CameraViews(views, rects, area, centres)
        return [d.k for d in detect(m, locs, box, 0.5, 0.35, cams, edge_radius=0.45)]

    assert found(rect, view) == [0]
    assert [d.k for d in detect(m, locs, box, 0.5, 0.35, view.max(0), edge_radius=0.45)] == [0, 4]
    apart = rect.copy()
    apart[0, 4] = [40, 10, 55, 59]
    assert found(apart, view) == [0, 4]
    unseen, out = rect.copy(), view.copy()
    unseen[1, 4], out[1, 4] = [0, 0, -1, -1], 0.0
    assert found(unseen, out) == [0, 4]
    assert found(rect[:1], view[:1], centre[:1]) == [0, 4]


def test_in_a_rig_a_detection_between_two_certain_cells_gives_way_to_them():
    """detection.give_way (docs/rig.md): cells A (0, 0), M (0.3, 0.2) and B (0.4, 0.4), rho*
    0.99998, 1 and 0.99995, M the strongest. By hand: M-A 0.361 m and M-B 0.224 m,
    both under the 0.4 m suppression radius, A-B 0.566 m, not: M suppresses two people, so in
    a rig of two cameras it gives way and A and B are the detections. M alone stays with one
    camera, with give_way 0 (off), where B is under give_way (0.99999), and where A and B are
    within the radius of each other (0.6 m: one person). The tracker's peaks go by the same rule."""
    from dpom_warp.detect import CameraViews
    from dpom_warp.tracking import Cells, peaks

    locs = grid_locations(5, 6)
    rect = np.tile([0, 0, 1, 1], (30, 1))
    a, m_, b = 0, 2 * 6 + 3, 4 * 6 + 4
    m = np.zeros((5, 6))
    m.flat[a], m.flat[m_], m.flat[b] = 0.99998, 1.0, 0.99995
    assert np.isclose(np.linalg.norm(locs[a] - locs[m_]), np.hypot(0.3, 0.2))
    assert np.isclose(np.linalg.norm(locs[a] - locs[b]), np.hypot(0.4, 0.4))
    rig, one = CameraViews(np.ones((2, 30))), CameraViews(np.ones((1, 30)))

    def found(views, give_way=0.99, radius=0.4):
        return [d.k for d in detect(m, locs, rect, 0.5, radius, views, give_way=give_way)]

    assert found(rig) == [a, b]
    assert found(one) == found(np.ones(30)) == found(None) == [m_]
    assert found(rig, give_way=0.0) == [m_]
    assert found(rig, give_way=0.99999) == [m_]
    assert found(rig, radius=0.6) == [m_]
    cells = Cells(locs, 0.1, np.zeros(30, bool), 0.4, rig, give_way=0.99)
    assert peaks(m, cells, 0.5).tolist() == [a, b]
    assert peaks(m, Cells(locs, 0.1, np.zeros(30, bool), 0.4, one, give_way=0.99), 0.5).tolist() == [m_]


def test_view_part_is_the_share_of_the_silhouette_rectangle_in_the_image():
    """Geometry.view_part from the box corners' projection: 1 where the rectangle is whole in
    the image, the clipped rectangle's share of the whole one at the edges, 0 with no
    silhouette."""
    cfg = load_config(str(ROOT / "configs" / "demo_people.yaml"))
    geom = build_geometry(cfg.camera, cfg.grid, cfg.obj)
    corners = cfg.obj.corners(geom.locations, cfg.grid.mode)
    u, v, z = cfg.camera.project(corners)
    seen = np.flatnonzero(geom.rect_area > 0)
    assert np.all(geom.view_part[geom.rect_area == 0] == 0)
    edge = 0
    for k in seen:
        if np.any(z[k] <= 1e-6):
            continue
        u0, u1 = np.ceil(u[k].min()), np.floor(u[k].max())
        v0, v1 = np.ceil(v[k].min()), np.floor(v[k].max())
        whole = (u1 - u0 + 1) * (v1 - v0 + 1)
        assert geom.view_part[k] == pytest.approx(geom.rect_area[k] / whole)
        edge += geom.view_part[k] < 1
    assert 0 < edge < len(seen) and np.all(geom.view_part[seen] > 0)


def test_the_match_gate_includes_its_distance():
    """"Within 0.5 m" includes 0.5 m (issue 63, boundaries): a detection exactly at the gate is
    matched, one a hair beyond is not (distances exact in binary: 0.5 = 0.3-0.4-0.5 triangle's
    hypotenuse), in the assignment and in MODA alike."""
    from dpom_warp.evaluate import score_frames
    from dpom_warp.matching import assign, match

    gt = np.array([[0.0, 0.0]])
    assert match(np.array([[0.3, 0.4]]), gt, 0.5) == [(0, 0)]  # 0.3^2 + 0.4^2 = 0.25 exactly in float64
    assert match(np.array([[0.3, 0.4000001]]), gt, 0.5) == []
    assert assign(np.array([[0.5, 0.7], [0.9, 0.5]]), 0.5) == [(0, 0), (1, 1)]
    truth = {"f": [{"x": 0.0, "y": 0.0, "visibility": 1.0}]}
    at = score_frames({"f": np.array([[0.5, 0.0]])}, truth, 0.5, 0.1, np.zeros(2))
    beyond = score_frames({"f": np.array([[0.5000001, 0.0]])}, truth, 0.5, 0.1, np.zeros(2))
    assert (at["tp"], at["fp"], at["moda"]) == (1, 0, 1.0)
    assert (beyond["tp"], beyond["fp"], beyond["fn"], beyond["moda"]) == (0, 1, 1, -1.0)
