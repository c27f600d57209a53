"""dpom-warp: people (and other objects) in depth images, with DPOM on Warp kernels.

commands:
  dpom-warp run CONFIG... [--output DIR] [--device D] [--set KEY.PATH=VALUE ...]
                [--workers N] [--ray [ADDRESS]] [--resume | --overwrite] [--max-frames N] [--play]
  dpom-warp fit-ground DEPTH... --camera CAMERA.yaml | RECORDING | realsense[:SERIAL] [--output POSE.yaml]
  dpom-warp calibrate CONFIG --output OUT.yaml [--set KEY.PATH=VALUE ...]
  dpom-warp eval RUN_DIR [--ground-truth GT.json] [--compare RUN_OR_CSV ...] [--plots]
  dpom-warp track RUN_DIR [--set tracking.KEY=VALUE ...] [--zones ZONES.yaml]
  dpom-warp info SOURCE [--topic TOPIC] [--json]
  dpom-warp schema [--output FILE]

`dpom-warp COMMAND --help` explains each; the README has the config reference.
"""

from __future__ import annotations

import argparse
import signal
import sys

from .config import ConfigError
from .loading import load_config
from .io import InputError, WorkerError


def _run(args) -> int:
    from pathlib import Path

    from .config import check_device
    from .pipeline import plan_run, run

    if args.overwrite and args.resume:
        raise ConfigError("--overwrite and --resume: expected at most one of them")
    if args.play and (args.ray is not None or args.resume):
        raise ConfigError(f"--play: frames sent as a live camera's are inferred in this process and its "
                          f"helpers, and a live run starts afresh; expected no {'--ray' if args.ray is not None else '--resume'}")
    if args.workers is not None and args.workers < 1:
        raise ConfigError(f"--workers: expected a number >= 1, found {args.workers}")
    if args.max_frames is not None and args.max_frames < 1:
        raise ConfigError(f"--max-frames: expected a number >= 1, found {args.max_frames}")
    if args.device:
        check_device(args.device, "--device")
    if args.ray is not None:
        import os

        from .cluster import import_ray, reachable
        import_ray()  # not installed: say so before any work
        address = args.ray or os.environ.get("RAY_ADDRESS")
        if address and address not in ("auto", "local"):
            reachable(address)  # nothing there: say so at once
    if args.view:
        from .view import _rerun

        _rerun()  # not installed: say so before any work
    sets = (args.set + ["output.view=true"] * args.view + ["input.play=true"] * args.play
            + ([f"counting.events={args.events}"] if args.events else []))
    cfgs = [load_config(c, sets) for c in args.config]
    outputs = output_dirs(args.config, cfgs, args.output)
    many = len(cfgs) > 1
    if args.ray is None:
        for source, cfg, out in zip(args.config, cfgs, outputs):
            if many:
                print(f"== {source}")
            summary = run(cfg, out, args.device, progress=not args.no_progress, strict=args.strict,
                          overwrite=args.overwrite, resume=args.resume, workers=args.workers,
                          max_frames=args.max_frames)
            _report(summary, out)
        return 0
    from .cluster import run_on_ray

    from .outputs import check_output

    for cfg, out in zip(cfgs, outputs):  # every output folder, before any setup
        check_output(Path(out), cfg.resolved, args.overwrite, args.resume)
    plans = []
    for source, cfg, out in zip(args.config, cfgs, outputs):
        if many:
            print(f"== {source}")
        plans.append(plan_run(cfg, out, "cpu", strict=args.strict, parallel=True, max_frames=args.max_frames))
    devices = [args.device or cfg.device for cfg in cfgs]
    summaries = run_on_ray(plans, [str(Path(c)) for c in args.config], devices, args.ray or None,
                           args.workers, args.overwrite, args.resume,
                           progress=not args.no_progress)
    for source, summary, out in zip(args.config, summaries, outputs):
        if many:
            print(f"== {source}")
        _report(summary, out)
    return 0


def output_dirs(sources: list[str], cfgs: list, output: str | None) -> list[str]:
    """Each config's output folder: --output (one config), --output/<config name> (several),
    else its output.dir; two runs may not share one."""
    from pathlib import Path

    if output and len(cfgs) > 1:
        outs = [str(Path(output) / Path(s).stem) for s in sources]
    else:
        outs = [output or cfg.output.dir for cfg in cfgs]
    seen = {}
    for source, out in zip(sources, outs):
        key = Path(out).resolve()
        if key in seen:
            raise ConfigError(f"output.dir: {seen[key]} and {source} both write to {out}; expected "
                              f"a folder per config")
        seen[key] = source
    return outs


def _report(summary: dict, out: str) -> None:
    if summary["skipped"]:
        print(f"{len(summary['skipped'])} frame(s) skipped (reasons in summary.json)")
    if summary.get("unconverged"):
        names = summary["unconverged"]
        cap = summary["config"]["model"]["max_iterations"]
        print(f"{len(names)} frame(s) stopped at model.max_iterations ({cap}) without converging: "
              f"{', '.join(names[:5])}{', ...' if len(names) > 5 else ''} (listed in summary.json)")
    live = summary.get("live")
    if live:
        print(f"live: {live['frames']} frames inferred of {live['received']} received ({live['dropped']} "
              f"dropped), {live['frames_per_s_steady'] or live['frames_per_s'] or 0:.1f} frames/s once running "
              f"({live['frames_per_s'] or 0:.1f} over the whole run), latency median "
              f"{live['latency_ms_median'] or 0:.0f} ms (stopped by {live['stopped_by']})")
    t = summary["timings"]
    n, found = summary["frames"], summary["detections"]
    print(f"{n} frame{'' if n == 1 else 's'}, {found} detection{'' if found == 1 else 's'}; median "
          f"{1000 * t['median_infer_s']:.0f} ms per frame ({t['median_iterations']:.0f} iterations) "
          f"on {summary['device']}; outputs in {out}")
    if summary.get("cameras"):  # a rig: where each camera's time went
        def ms(v):
            return "-" if v is None else f"{1000 * v:.0f}"

        print("cameras, median ms a frame (reading + lists + its pixels in the mean field): " + "; ".join(
            f"{name} {ms(c['median_read_s'])} + {ms(c['median_lists_s'])} + {ms(c['median_iterations_s'])} "
            f"({c['frames']} frames{', ' + str(len(c['missing'])) + ' missing' if c['missing'] else ''})"
            for name, c in summary["cameras"].items()))
    tr = summary.get("tracking") or {}
    if tr.get("method", "off") != "off":
        print(f"{tr['tracks']} tracks ({tr['method']}, {tr['ms_per_frame']:.1f} ms per frame): "
              f"{out}/tracks.csv")
    s = summary.get("scores")
    if s:
        print(f"MODA {s['moda']:.3f}  precision {s['precision']:.3f}  recall {s['recall']:.3f}  "
              f"at {s['match_distance']} m ({s['n_gt']} in the ground truth; MODA "
              f"{s['moda_visible']:.3f} not penalising those less than {s['hidden_visibility']:.0%} visible)")


def _positive(text: str) -> int:
    """An integer >= 1."""
    try:
        n = int(text)
    except ValueError:
        n = 0
    if n < 1:
        raise argparse.ArgumentTypeError(f"expected an integer >= 1, found {text!r}")
    return n


def _up_arg(text: str):
    """--up: "auto" or three numbers, not all zero."""
    if text == "auto":
        return text
    try:
        up = tuple(float(v) for v in text.split(","))
    except ValueError:
        up = ()
    if len(up) != 3 or not any(up):
        raise argparse.ArgumentTypeError(f"expected auto or three numbers X,Y,Z not all 0, found {text!r}")
    return up


def _fit_ground(args) -> int:
    import os

    import yaml

    from .config import load_camera_file
    from .ground import GroundOptions, fit_ground_files, fit_ground_named, frames_named, noise_words
    from .sources import recording_frames
    from .io import InputError, write_text_atomic
    from .names import is_live, is_recording

    camera, scale = load_camera_file(args.camera) if args.camera else (None, None)
    up = args.up
    if len(args.depth) == 1 and (is_recording(args.depth[0]) or is_live(args.depth[0])):
        camera, frames, names, gravity = recording_frames(args.depth[0], args.topic, args.frames, camera)
        if up == "auto" and gravity:  # the accelerometer says where up is, as in a run
            up = tuple(float(x) for x in gravity)
            print(f"up from the {'camera' if is_live(args.depth[0]) else 'recording'}'s accelerometer: "
                  f"[{', '.join(f'{x:.4f}' for x in up)}]", file=sys.stderr)
        options = GroundOptions(up=up, max_angle_deg=args.max_angle, depth_max=args.depth_max)
        fit = fit_ground_named(frames, camera, options, frames_named(frames, names))
        count = len(frames)
    else:
        from .sources.files import FileFrames

        if camera is None:
            raise InputError("--camera: expected a camera YAML (width, height, intrinsics, depth_scale) for "
                             "depth image files; found none (a recording, given alone, carries its own)")
        files = [f for d in args.depth  # a folder or a quoted glob: its frame files, as input.frames takes them
                 for f in (FileFrames(d, "DEPTH").files if os.path.isdir(d) or any(c in d for c in "*?[") else [d])]
        options = GroundOptions(up=up, max_angle_deg=args.max_angle, depth_max=args.depth_max)
        fit = fit_ground_files(files, camera, scale, options)
        count = len(files)
    if fit.ambiguity:
        print(f"dpom-warp: warning: {fit.ambiguity}", file=sys.stderr)
    report = fit.report()
    text = (f"# dpom-warp fit-ground on {count} frame(s); paste under camera.extrinsics\n"
            + yaml.safe_dump(report, default_flow_style=None, sort_keys=False))
    if args.output:
        write_text_atomic(args.output, text)
    print(f"camera {fit.camera_height:.3f} m above the floor, pitch {fit.pitch_deg:.2f} deg, roll "
          f"{fit.roll_deg:.2f} deg; {fit.inlier_count} floor points, rms {1000 * fit.rms_m:.1f} mm"
          + (f"; pose written to {args.output}" if args.output else ""))
    if fit.floor_xy is not None:  # where a grid goes (people nearer than its near edge may be in view too)
        x0, x1, y0, y1 = fit.floor_xy
        print(f"floor in view within {args.depth_max:g} m, in this pose's world: x {x0:g} to {x1:g} m, "
              f"y {y0:g} to {y1:g} m")
    if fit.noise is not None:  # the sensor's noise, for model.sensor_noise
        print(f"depth noise on the floor: {noise_words(fit.noise)}: model.sensor_noise about "
              f"[{fit.noise['a']:g}, {fit.noise['b']:g}]")
    if not args.output:
        print(text, end="")
    return 0


def eval_output(run: str, compare: list[str], output: str | None):
    """Where `eval` writes: --output; else the run's folder (beside a CSV); with --compare a
    folder of its own beside the first run, named after what was compared, so a run's own
    eval.json and plots are never replaced."""
    from pathlib import Path

    if output:
        return Path(output)
    first = Path(run)
    home = first if first.is_dir() else first.parent
    if not compare:
        return home
    names = [Path(p).name if Path(p).is_dir() else Path(p).stem for p in [run] + compare]
    return home.parent / ("eval_" + "_vs_".join(names))


def _eval(args) -> int:
    from .evaluate import evaluate_runs, markdown_table, tracking_table
    from .io import write_json_atomic
    from .writers import jsonable

    results = evaluate_runs([args.run] + args.compare, args.ground_truth, args.hidden_visibility,
                            args.min_rho)
    out = eval_output(args.run, args.compare, args.output)
    write_json_atomic(out / "eval.json", jsonable(results))
    print(markdown_table(results))
    tracks = tracking_table(results)
    if tracks:
        print("\n" + tracks)
    print(f"\ncurves in {out / 'eval.json'}")
    if args.plots:
        from .plots import write_figures

        made = write_figures(results, out / "plots")
        print(f"figures: {', '.join(str(out / 'plots' / m) for m in made)}")
    return 0


def _track(args) -> int:
    from .pipeline import retrack

    sets = list(args.set)
    if args.zones:  # the file's zones, lines and counting, as --set items
        import json

        from pathlib import Path

        from .values import _read_yaml

        given = _read_yaml(Path(args.zones), "zones file (--zones)")
        if not isinstance(given, dict) or not set(given) <= {"zones", "lines", "counting"} or not given:
            raise ConfigError(f"--zones {args.zones}: expected a mapping of zones:, lines: and counting:, found "
                              f"{sorted(given) if isinstance(given, dict) else type(given).__name__}")
        sets += [f"{k}={json.dumps(v)}" for k, v in given.items()] + [f"{k}=[]" for k in ("zones", "lines")
                                                                        if k not in given]
    report = retrack(args.run, sets)
    print(f"{report.get('tracks', 0)} tracks ({report['method']}); tracks.csv and track_table.csv in "
          f"{args.run}" if report["method"] != "off" else
          f"no tracks in {args.run}: {report['why']} (--set tracking.method=ksp|online tracks any run)")
    return 0


def _info(args) -> int:
    import json

    import numpy as np

    from .ground import implied_pitch_roll
    from .sources import open_source

    info = open_source(args.source, args.topic, "SOURCE").info().as_json()
    if args.json:
        print(json.dumps(info, indent=2))
        return 0
    i, d = info["intrinsics"], info["distortion"]
    tilt = implied_pitch_roll(np.asarray(info["gravity_up"], dtype=np.float64)) if info.get("gravity_up") else None
    lines = [f"{info['path']}: {info['kind']}",
             f"  depth stream: {info['topic'] or '-'} ({info['encoding'] or '-'}), {info['frames']} "
             f"frame{'' if info['frames'] == 1 else 's'} of {info['width']}x{info['height']}",
             "  intrinsics: " + (f"fx {i['fx']:.3f}, fy {i['fy']:.3f}, cx {i['cx']:.3f}, cy {i['cy']:.3f}"
                                  if i else "none (give camera.intrinsics in the config)"),
             "  distortion: " + (f"[{', '.join(f'{x:.6g}' for x in d)}]" if d else "none"),
             "  depth scale: " + (f"{info['depth_scale']:.7g} m per unit" if info["depth_scale"]
                                   else "float metres" if info["encoding"] == "32FC1" else "-"),
             "  duration: " + (f"{info['duration_s']:.3f} s, {info['rate_hz']:.2f} frames/s"
                                if info["duration_s"] else "-"),
             f"  IMU: {'yes' if info['imu'] else 'no'}" + (
                 f" (up in the depth camera's frame: [{', '.join(f'{x:.4f}' for x in info['gravity_up'])}]: "
                 f"pitch {tilt[0]:.2f} deg, roll {tilt[1]:.2f} deg"
                 f"{', as camera.extrinsics {height: H} takes them' if tilt[0] <= 90 else ''})"
                 if tilt else "")]
    if len(info["streams"]) > 1:
        lines.append(stream_lines(info["streams"]))
    bad = info["unreadable"]
    if bad:  # a folder's files a run skips, each with its reason
        lines.append(f"  not readable: {len(bad)} of {len(bad) + info['frames']} files (a run skips them):")
        lines += [f"    {b['reason']}" for b in bad[:10]] + ([f"    ... and {len(bad) - 10} more"] if len(bad) > 10 else [])
    print("\n".join(lines))
    return 0


SENSOR_TYPES = ("Image", "CameraInfo", "Imu", "PointCloud", "video", "subtitle")  # what `info` lists by name


def stream_lines(streams: list[dict]) -> str:
    """`info`'s streams line: those carrying sensor data (images, camera models, IMU, point
    clouds; a Matroska file's tracks) by name with their type and messages, the others (a
    RealSense recording's option values and device records: dozens) counted by type."""
    def one(s):
        return f"{s['topic']} ({s['type']}" + (f", {s['messages']}" if s.get("messages") else "") + ")"

    shown = [s for s in streams if any(t in s["type"] for t in SENSOR_TYPES)]
    rest = [s for s in streams if s not in shown]
    line = "  streams: " + "; ".join(one(s) for s in shown or streams[:8])
    rest = rest if shown else streams[8:]
    if rest:
        from collections import Counter

        kinds = Counter(s["type"] for s in rest).most_common()  # (ties in order of first appearance)
        line += f"; and {len(rest)} more (" + ", ".join(f"{k} {n}" for k, n in kinds) + "; --json lists them)"
    return line


def _schema(args) -> int:
    import json

    from .config import json_schema
    from .io import write_text_atomic

    text = json.dumps(json_schema(), indent=2) + "\n"
    if args.output:
        write_text_atomic(args.output, text)
        print(f"JSON Schema of the run config written to {args.output}")
    else:
        print(text, end="")
    return 0


def _terminate(signum, frame):
    raise KeyboardInterrupt


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Descriptions as written (one usage line each), and each option's default in its help
    (options without a default say in their own words what happens without them)."""

    def _get_help_string(self, action):
        text = action.help or ""
        if ("%(default)" in text or action.default in (None, False, [], argparse.SUPPRESS)
                or not action.option_strings):
            return text
        return f"{text} (default: %(default)s)"


def parser() -> argparse.ArgumentParser:
    """The command line: each command with its arguments."""
    from . import __version__

    parser = argparse.ArgumentParser(prog="dpom-warp", description=__doc__, formatter_class=HelpFormatter)
    parser.add_argument("--version", action="version", version=f"dpom-warp {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    def command(name, text, description):
        return sub.add_parser(name, help=text, description=description, formatter_class=HelpFormatter)

    p = command("run", "run DPOM over a sequence of depth frames",
                "Run DPOM over a config's depth frames: detections.csv, maps, tracks.csv, pictures,\n"
                "summary.json "
                "(and scores with ground truth) in the output folder. Relative paths in a config are\n"
                "relative to the config file's folder; paths given with --set, to this folder.")
    _run_arguments(p)
    g = command("fit-ground", "find the floor and the camera pose from depth frames",
                "Fit the floor plane in depth frames of one camera and print (or write) the pose to\n"
                "paste under a config's camera.extrinsics.")
    c = command("calibrate", "place a rig's cameras in one world from what they see",
                "Place every camera of a rig config (cameras:) in one world whose floor is z = 0: each\n"
                "camera's floor fit gives its height, pitch and roll; its yaw and position on the floor\n"
                "come from the static scene it sees in common with the others (docs/rig.md).\n"
                "Writes the config with every camera's extrinsics to --output, which runs as it is.")
    c.add_argument("config", help="a rig config (YAML with a cameras: list)")
    c.add_argument("--output", required=True, help="the calibrated config written here")
    c.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a config value before calibrating (as for run)")
    g.add_argument("depth", nargs="+", help="depth frames (16-bit PNG or .npy; folders and globs of them) of the "
                                            "same camera, or one recording (ROS bag, Azure Kinect .mkv): its "
                                            "first --frames frames, or a live camera (realsense[:SERIAL]): its "
                                            "next --frames frames")
    g.add_argument("--camera", help="camera YAML: width, height, intrinsics, depth_scale (required for frame "
                                    "files; a recording's own camera otherwise)")
    g.add_argument("--topic", help="a recording's depth topic, where it has several (as input.topic)")
    g.add_argument("--frames", type=_positive, default=5, metavar="N",
                   help="a recording: fit on its first N readable depth frames (as camera.ground.frames)")
    g.add_argument("--output", help="write the pose YAML here (default: print it)")
    g.add_argument("--up", default="auto", type=_up_arg, metavar="auto|X,Y,Z",
                   help="the up direction in the camera frame (camera.ground.up): auto (default) takes "
                        "the floor of any camera from level to straight down; 0,-1,0 the image's up, "
                        "0,0,-1 a camera looking down")
    g.add_argument("--max-angle", type=float, default=45.0,
                   help="largest angle between the floor normal and --up (degrees; auto: the largest roll)")
    g.add_argument("--depth-max", type=float, default=6.0, help="ignore readings beyond (metres)")
    e = command("eval", "score runs (or detection CSVs) against ground truth",
                "Score a run folder (and, with --compare, more runs or detection CSVs) against ground\n"
                "truth: MODA and MODP curves, precision-recall, average precision, plots.")
    e.add_argument("run", help="a dpom-warp run folder, or a detections CSV")
    e.add_argument("--ground-truth", help="ground-truth JSON (default: the run's evaluation.ground_truth)")
    e.add_argument("--compare", nargs="+", default=[], metavar="RUN_OR_CSV",
                   help="more run folders or detections CSVs on the same plots and table")
    e.add_argument("--plots", action="store_true", help="write PNG figures into OUTPUT/plots")
    e.add_argument("--output", help="where eval.json and plots go (default: the run's folder; with "
                                    "--compare, eval_RUN_vs_OTHER... beside it)")
    e.add_argument("--hidden-visibility", type=float, default=0.1,
                   help="people less visible than this are not penalised in the second protocol")
    e.add_argument("--min-rho", type=float, default=0.05,
                   help="lowest rho* re-detected from the maps for the threshold sweep")
    t = command("track", "track a finished run again with other tracking settings",
                "Compute a finished run's tracks again from its maps (no inference): tracks.csv,\n"
                "track_table.csv, the pictures, summary.json's tracking block and eval.json.")
    t.add_argument("run", metavar="RUN_DIR", help="a dpom-warp run folder")
    t.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override tracking.*, input.fps, output.images, zones, lines or counting.*, e.g. --set "
                        "tracking.method=online; repeatable")
    t.add_argument("--zones", metavar="FILE", help="a YAML file of zones:, lines: (and counting:) counted instead of "
                                                  "the run's")
    n = command("info", "what a recording or a folder of frames holds",
                "Print what a recording (.bag, .db3, .mcap, a ROS 2 bag folder, .mkv) or a glob of\n"
                "depth frames holds: depth stream, frames, size, intrinsics, distortion, depth scale,\n"
                "duration and rate, IMU, the other streams.")
    n.add_argument("source", metavar="SOURCE", help="a recording, or a glob of depth frames (quote it)")
    n.add_argument("--topic", help="the depth stream, when the recording has several")
    n.add_argument("--json", action="store_true", help="print JSON (frames, width, height, intrinsics, "
                                                       "depth_scale, ...)")
    m = command("schema", "write the JSON Schema of run configs (for editors)",
                "Write the JSON Schema of run configs: point an editor's YAML support at it to\n"
                "complete and check configs (configs/dpom-warp.schema.json is this output).")
    m.add_argument("--output", help="write it to this file (default: print it)")
    return parser


def _run_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("config", nargs="+", metavar="CONFIG", help="YAML run config (see README); several: one run each, "
                                             "each to its own output")
    p.add_argument("--output", metavar="DIR", help="output folder (default: the config's output.dir); with several "
                                    "configs each run writes to OUTPUT/<config name>")
    p.add_argument("--device", metavar="DEVICE", help="auto, cpu or cuda:N (default: the config's device)")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a config value (parsed as YAML), e.g. --set model.damping=0.2; "
                        "repeatable")
    p.add_argument("--events", metavar="PATH", help="stream each committed frame's zone counts and line crossings "
                                                  "as JSON lines to PATH (-: standard output; counting.events)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--strict", action="store_true", help="a bad frame is fatal instead of skipped")
    p.add_argument("--workers", type=int, default=None, metavar="N",
                   help="infer frames in this many processes (Warp runs CPU kernels on one thread); "
                        "with --ray, this many actors (default: 1; a live camera on the CPU: 3 where "
                        "there are two CPUs or more; with --ray one actor per CPU, or GPU, of the cluster)")
    p.add_argument("--ray", nargs="?", const="", metavar="ADDRESS",
                   help="infer frames on Ray actors: of the cluster at ADDRESS (or $RAY_ADDRESS; "
                        "'auto': the one `ray start` runs here), else of a new local Ray instance; "
                        "needs the [ray] extra (default: no Ray)")
    p.add_argument("--overwrite", action="store_true", help="replace the results in a non-empty output folder")
    p.add_argument("--resume", action="store_true",
                   help="continue an interrupted run in its output folder, skipping finished frames")
    p.add_argument("--view", action="store_true",
                   help="show the run in a Rerun viewer, spawned (the [view] extra; output.rerun writes a .rrd)")
    p.add_argument("--play", action="store_true",
                   help="send input.frames (files at input.fps, a recording at its timestamps) as a live camera "
                        "would: the newest frame inferred, the others dropped; live mode without a camera "
                        "(input.play)")
    p.add_argument("--max-frames", type=int, metavar="N",
                   help="the first N frames of input.frames (a recording's by its stream; default: all); a "
                        "live camera (input.frames: realsense): stop after N frames (default: at Ctrl-C)")


def _calibrate(args) -> int:
    from .calibrate import calibrate

    calibrate(args.config, args.output, args.set)
    return 0


COMMANDS = {"run": _run, "fit-ground": _fit_ground, "calibrate": _calibrate, "eval": _eval, "schema": _schema, "track": _track, "info": _info}


def _closed_pipe(command: str) -> int:
    """Standard output closed by its reader: the commands that only print end quietly (exit 0);
    a run, whose frames are written to files, says how to go on (exit 1)."""
    import os

    try:  # Python's own flush at exit would raise on the closed pipe again
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except OSError:
        pass
    if command in ("info", "schema", "eval"):
        return 0
    print("dpom-warp: error: standard output was closed; finished frames are kept, continue with --resume",
          file=sys.stderr)
    return 1


def main(argv: list[str] | None = None) -> int:
    args = parser().parse_args(argv)
    signal.signal(signal.SIGTERM, _terminate)  # a kill unwinds like Ctrl-C: no partial files
    try:
        return COMMANDS[args.command](args)
    except (ConfigError, InputError) as e:
        print(f"dpom-warp: error: {e}", file=sys.stderr)
        return 2
    except WorkerError as e:
        print(f"dpom-warp: error: {e}", file=sys.stderr)
        return 1
    except BrokenPipeError:  # a reader that stopped early (`dpom-warp info REC --json | head -1`)
        return _closed_pipe(args.command)
    except OSError as e:  # a write that failed (disk full, permissions): finished frames are kept
        where = f"{e.filename}: " if getattr(e, "filename", None) else ""
        print(f"dpom-warp: error: {where}{e.strerror or e}; finished frames are kept, continue with --resume",
              file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("dpom-warp: interrupted; finished frames are kept, continue with --resume",
              file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
