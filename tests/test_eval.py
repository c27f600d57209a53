"""`dpom-warp eval`: matching and metrics on hand-computed cases, and the command itself."""

import csv
import json

import numpy as np
import pytest

from dpom_warp.cli import main
from dpom_warp.config import parse_config
from dpom_warp.evaluate import (Detections, box_iou, counts, moda_curve, pr_curve,
                                read_detections_csv, run_detections)
from dpom_warp.io import InputError

from test_cli import small_config
from pictures import assert_picture


def dets(frames):
    return Detections("d", {k: np.array(v, float).reshape(-1, 8) for k, v in frames.items()})


def test_box_iou_hand_computed():
    a = np.array([[0, 0, 9, 9]])  # 10 x 10 pixels
    b = np.array([[5, 0, 14, 9], [20, 20, 29, 29], [0, 0, 9, 9]])
    np.testing.assert_allclose(box_iou(a, b), [[50 / 150, 0.0, 1.0]])


TRUTH = {
    "a": [{"x": 0, "y": 0, "bbox": [0, 0, 9, 19], "visibility": 1.0},
          {"x": 2, "y": 0, "bbox": [40, 0, 49, 19], "visibility": 0.05}],
    "b": [{"x": 1, "y": 1, "bbox": [10, 0, 19, 19], "visibility": 0.8}],
    "empty": [],
}


def test_counts_ground_with_ties_hidden_and_empty_frames():
    d = dets({
        # two detections 0.2 m from the same person: a tie; one matches, the other is false
        "a": [[0.2, 0, 0, 0.9, 0, 0, 9, 19], [-0.2, 0, 0, 0.8, 0, 0, 9, 19], [2.1, 0, 0, 0.7, 40, 0, 49, 19]],
        "b": [],  # no detections: the person is missed
        "empty": [[5, 5, 0, 0.95, 0, 0, 1, 1]],  # a detection where nobody is
    })
    c = counts(d, TRUTH, 0.5, "ground", 0.5)
    assert (c["tp"], c["fp"], c["fn"], c["n_gt"]) == (2, 2, 1, 3)
    assert c["moda"] == pytest.approx(1 - 3 / 3)
    assert c["modp"] == pytest.approx(((1 - 0.2 / 0.5) + (1 - 0.1 / 0.5)) / 2)
    # hidden person (visibility 0.05) ignored: its detection is neither right nor wrong
    c = counts(d, TRUTH, 0.5, "ground", 0.5, hidden_visibility=0.1, penalise_hidden=False)
    assert (c["tp"], c["fp"], c["fn"], c["n_gt"]) == (1, 2, 1, 2)
    # a higher threshold drops the 0.7 and 0.8 detections
    c = counts(d, TRUTH, 0.85, "ground", 0.5)
    assert (c["tp"], c["fp"], c["fn"]) == (1, 1, 2)
    # no ground truth at all
    none = counts(d, {"empty": []}, 0.5, "ground", 0.5)
    assert none["n_gt"] == 0 and np.isnan(none["moda"]) and none["fp"] == 1


def test_counts_image_plane():
    d = dets({"a": [[9, 9, 0, 0.9, 0, 0, 9, 14], [9, 9, 0, 0.9, 45, 0, 54, 19]], "b": [[9, 9, 0, 0.6, 10, 0, 19, 19]]})
    c = counts(d, TRUTH, 0.5, "image", 0.5)  # IoU 150/200 = 0.75, 50/150 = 0.33, 1.0
    assert (c["tp"], c["fp"], c["fn"]) == (2, 1, 1)
    assert c["modp"] == pytest.approx((0.75 + 1.0) / 2)
    assert counts(d, TRUTH, 0.5, "image", 0.3)["tp"] == 3


def test_pr_curve_and_average_precision_hand_computed():
    truth = {"f": [{"x": 0, "y": 0}, {"x": 3, "y": 0}]}
    d = dets({"f": [[0, 0, 0, 0.9, 0, 0, 1, 1], [9, 9, 0, 0.8, 0, 0, 1, 1], [3, 0, 0, 0.7, 0, 0, 1, 1]]})
    pr = pr_curve(d, truth, "ground", 0.5, 0.0, True)
    assert [(p["precision"], p["recall"]) for p in pr["points"]] == [
        (1.0, 0.5), (0.5, 0.5), (pytest.approx(2 / 3), 1.0)]
    assert pr["ap"] == pytest.approx(0.5 * 1.0 + 0.5 * 2 / 3)
    curve = moda_curve(d, truth, "ground", [0.5], 0.0, True)
    assert curve[0]["moda"] == pytest.approx(0.5) and curve[0]["threshold"] in (0.9, 0.7)
    empty = pr_curve(dets({"f": []}), truth, "ground", 0.5, 0.0, True)
    assert empty["points"] == [] and np.isnan(empty["ap"])


def test_csv_reading_and_errors(tmp_path):
    p = tmp_path / "other.csv"
    p.write_text("frame,x,y,rho\na,0,0,0.9\n")
    d = read_detections_csv(p)
    assert not d.has_boxes and d.frames["a"].shape == (1, 8)
    p.write_text("frame,x,rho\na,0,0.9\n")
    with pytest.raises(InputError, match="expected a CSV header with frame, x, y, rho"):
        read_detections_csv(p)
    p.write_text("frame,x,y,rho\na,0,zero,0.9\n")
    with pytest.raises(InputError, match="line 2: expected numbers"):
        read_detections_csv(p)


def test_resolved_config_parses_back_to_itself(tmp_path):
    from dpom_warp.loading import load_config

    cfg = load_config(small_config(tmp_path))
    assert parse_config(cfg.resolved).resolved == cfg.resolved


def test_eval_command_on_a_run_and_a_csv(tmp_path, capsys):
    path = small_config(tmp_path)
    assert main(["run", str(path), "--no-progress"]) == 0
    out = tmp_path / "out"
    run_eval = json.load(open(out / "eval.json"))  # the run wrote the curves already
    # re-detected candidates at the run's threshold are exactly the CSV's detections
    cands, summary, cube = run_detections(out)
    assert cube is None  # a ground grid
    rows = list(csv.DictReader(open(out / "detections.csv")))
    for frame, arr in cands.frames.items():
        kept = arr[arr[:, 3] >= summary["config"]["detection"]["threshold"]]
        mine = sorted((round(x, 4), round(y, 4)) for x, y in kept[:, :2])
        theirs = sorted((float(r["x"]), float(r["y"])) for r in rows if r["frame"] == frame)
        assert len(mine) == len(theirs)
        np.testing.assert_allclose(np.array(mine).reshape(-1, 2), np.array(theirs).reshape(-1, 2))
    other = tmp_path / "other.csv"
    other.write_text("frame,x,y,rho\n" + "".join(f"{r['frame']},{float(r['x']) + 0.3},{r['y']},{r['rho']}\n"
                                                  for r in rows))
    capsys.readouterr()
    assert main(["eval", str(out), "--compare", str(other), "--plots", "--output", str(tmp_path / "ev")]) == 0
    printed = capsys.readouterr().out
    assert "| out | hidden penalised |" in printed and "| other | hidden penalised |" in printed
    results = json.load(open(tmp_path / "ev" / "eval.json"))
    assert [r["name"] for r in results] == ["out", "other"]
    assert results[0]["penalise_hidden"] == run_eval[0]["penalise_hidden"]
    assert "moda_image" in results[0]["penalise_hidden"] and "moda_image" not in results[1]["penalise_hidden"]
    # shifting every detection by 0.3 m: fewer matches at 0.2 m, same at 0.5 m
    g0 = {c["gate"]: c for c in results[0]["penalise_hidden"]["moda_ground"]}
    g1 = {c["gate"]: c for c in results[1]["penalise_hidden"]["moda_ground"]}
    assert g1[0.2]["tp"] <= g0[0.2]["tp"] and g1[1.0]["tp"] == g0[1.0]["tp"]
    for name in ("moda_ground.png", "pr_ground.png", "moda_image.png", "pr_image.png"):
        assert_picture(tmp_path / "ev" / "plots" / name, (300, 200), plot=True)


def test_eval_errors(tmp_path, capsys):
    assert main(["eval", str(tmp_path)]) == 2
    assert "not a dpom-warp run folder" in capsys.readouterr().err
    p = tmp_path / "d.csv"
    p.write_text("frame,x,y,rho\n")
    assert main(["eval", str(p)]) == 2
    assert "expected --ground-truth GT.json for a CSV" in capsys.readouterr().err
    assert main(["eval", str(tmp_path / "gone")]) == 2
    assert f"{tmp_path / 'gone'}: no such run folder or detections CSV" in capsys.readouterr().err


def test_cube_overlap_and_3d_distance_hand_computed():
    from dpom_warp.evaluate import cube_iou, evaluate

    size = (0.4, 0.4, 0.12)
    a = np.array([[0.0, 0.0, 1.0]])
    b = np.array([[0.2, 0.0, 1.0], [0.0, 0.0, 1.06], [0.0, 0.0, 1.5]])
    # half the width apart: 0.2 x 0.4 x 0.12 shared of 2 x 0.4 x 0.4 x 0.12 minus it
    np.testing.assert_allclose(cube_iou(a, b, size), [[1 / 3, 1 / 3, 0.0]])
    truth = {"f": [{"x": 0, "y": 0, "z": 1.0}, {"x": 2, "y": 0, "z": 2.0}]}
    d = dets({"f": [[0.0, 0.0, 1.2, 0.9, -1, -1, -1, -1], [2.0, 0.0, 2.05, 0.8, -1, -1, -1, -1]]})
    # in 3D the first detection is 0.2 m off (height), on the ground it would be exact
    c = counts(d, truth, 0.5, "space", 0.15)
    assert (c["tp"], c["fp"], c["fn"]) == (1, 1, 1)
    assert counts(d, truth, 0.5, "ground", 0.15)["tp"] == 2
    c = counts(d, truth, 0.5, "cube", 0.5, cube_size=size)  # IoU 0 and (0.07/0.17)
    assert c["tp"] == 0
    c = counts(d, truth, 0.5, "cube", 0.25, cube_size=size)
    assert c["tp"] == 1 and c["modp"] == pytest.approx(0.07 / 0.17)
    r = evaluate(d, truth, cube_size=size)
    assert r["distance"] == "space" and "moda_cube" in r["penalise_hidden"]
    assert [c["gate"] for c in r["penalise_hidden"]["moda_cube"]] == pytest.approx([0.1 * i for i in range(1, 10)])
    assert r["penalise_hidden"]["moda_cube"][0]["tp"] == 1  # IoU >= 0.1
