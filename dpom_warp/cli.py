"""Command line: `dpom-warp run CONFIG [--output DIR] [--device D] [--set key.path=value ...]`."""

from __future__ import annotations

import argparse
import sys

from .config import ConfigError, load_config
from .io import InputError


def _run(args) -> int:
    from .engine import ListOverflow
    from .pipeline import run

    cfg = load_config(args.config, args.set)
    try:
        summary = run(cfg, args.output, args.device, progress=not args.no_progress)
    except ListOverflow as e:
        raise InputError(str(e)) from None
    t = summary["timings"]
    print(f"{summary['frames']} frames, {summary['detections']} detections; median "
          f"{1000 * t['median_infer_s']:.0f} ms per frame ({t['median_iterations']:.0f} iterations) "
          f"on {summary['device']}; outputs in {args.output or cfg.output.dir}")
    s = summary.get("scores")
    if s:
        print(f"MODA {s['moda']:.3f}  precision {s['precision']:.3f}  recall {s['recall']:.3f}  "
              f"at {s['match_distance']} m ({s['n_gt']} people; MODA {s['moda_visible']:.3f} "
              f"not penalising people less than {s['hidden_visibility']:.0%} visible)")
    return 0


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="dpom-warp", description=__doc__)
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("run", help="run DPOM over a sequence of depth frames")
    p.add_argument("config", help="YAML run config (see README)")
    p.add_argument("--output", help="output folder (overrides output.dir)")
    p.add_argument("--device", help="auto, cpu or cuda:N (overrides device)")
    p.add_argument("--set", action="append", default=[], metavar="KEY.PATH=VALUE",
                   help="override a config value, e.g. --set model.damping=0.2")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    args = parser.parse_args(argv)
    try:
        if args.command == "run":
            return _run(args)
    except (ConfigError, InputError) as e:
        print(f"dpom-warp: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("dpom-warp: interrupted", file=sys.stderr)
        return 130
    return 1


if __name__ == "__main__":
    sys.exit(main())
