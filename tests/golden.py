"""Golden outputs: digests of what every config and bench scene writes, recorded before a
refactor and compared after it (issue 58: byte-identical detections, maps and tracks).

    python tests/golden.py            # record tests/golden.json from the working tree

What is compared, per run: detections.csv, tracks.csv, track_table.csv and every maps/*.npy
byte for byte (sha256), and each frame record's counts (iterations, converged, live list
entries, entries, kept entries, detections): the timings and the worker's name are left out,
as are the pictures (matplotlib's bytes are not the engine's). Each run is the CLI's
`dpom-warp run` with pictures off, so the recorded bytes are what a user's run writes.

The maps' last bits depend on the CPU: Warp compiles its CPU kernels for the host
(`-march=native`), and NumPy and the C library choose code paths by its features (an AMD EPYC
and an Intel Xeon VM gave detections, tracks and their files byte for byte alike, and maps and
list entries a few in 10^5 apart). So each run also records the machine it ran on (`machine()`)
and each map's sum and count of cells at rho* >= 0.5: on that machine the maps and counts are
compared byte for byte, elsewhere to those sums and counts (test_golden).
"""

from __future__ import annotations

import hashlib
import json
import platform
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
GOLDEN = Path(__file__).with_name("golden.json")
FILES = ("detections.csv", "tracks.csv", "track_table.csv")
COUNTS = ("frame", "detections", "iterations", "converged", "live", "entries", "kept_entries")


def _bench_sets(name: str, exact: bool) -> tuple[str, list[str]]:
    """The bench scene's config and overrides as bench.load_scene makes them (2 frames)."""
    sys.path.insert(0, str(ROOT))
    from bench.scenes import scene_sets

    path, sets = scene_sets(name)
    return path, sets + ["engine.exact=true"] * exact


def scenarios() -> dict[str, tuple[str, list[str]]]:
    """name -> (config path relative to the repository, --set overrides)."""
    runs = {Path(c).stem: (f"configs/{Path(c).name}", []) for c in sorted((ROOT / "configs").glob("*.yaml"))}
    for scene in ("kinect_v2", "kinect_v2_far", "kinect_v1", "drones"):
        for exact in (False, True):
            if exact and scene == "kinect_v1":
                continue  # 46 s on the 2-core VM for the exact path's 640x480 at 0.05 m: the
                # same kernels as kinect_v2's exact run, which is kept
            runs[f"bench_{scene}{'_exact' if exact else ''}"] = _bench_sets(scene, exact)
    return runs


def run_scenario(name: str, out: Path) -> Path:
    """`dpom-warp run` of one scenario into out/name (from the repository root: the bench
    scenes' caches are relative to it), pictures off; returns the run folder."""
    import os

    from dpom_warp.cli import main

    config, sets = scenarios()[name]
    folder = out / name
    here = os.getcwd()
    os.chdir(ROOT)
    try:
        argv = ["run", config, "--output", str(folder), "--no-progress", "--set", "output.images=false",
                "--set", "evaluation.plots=false"]
        for s in sets:
            argv += ["--set", s]
        code = main(argv)
    finally:
        os.chdir(here)
    assert code == 0, f"{name}: dpom-warp run exited {code}"
    return folder


def machine() -> str:
    """What the maps' last bits depend on: the processor's model and the instruction-set
    features NumPy finds on it (Warp's CPU kernels are compiled for the host's)."""
    try:
        from numpy._core._multiarray_umath import __cpu_features__ as features
    except ImportError:  # NumPy 1
        from numpy.core._multiarray_umath import __cpu_features__ as features
    model = platform.processor()
    try:
        model = next(line.split(":", 1)[1].strip() for line in Path("/proc/cpuinfo").read_text().splitlines()
                     if line.startswith("model name"))
    except (OSError, StopIteration):
        pass
    enabled = ",".join(sorted(k for k, on in features.items() if on))
    return f"{platform.machine()} {model} [{hashlib.sha256(enabled.encode()).hexdigest()[:12]}]"


def digest(folder: Path) -> dict:
    """What must stay byte-identical in a run folder (on the machine that ran it; `map_sums`,
    each map's sum and count of cells at rho* >= 0.5, to compare with on another)."""
    out = {"machine": machine()}
    for name in FILES:
        path = folder / name
        out[name] = hashlib.sha256(path.read_bytes()).hexdigest() if path.exists() else None
    maps = sorted((folder / "maps").glob("*.npy"))
    out["maps"] = {p.name: hashlib.sha256(p.read_bytes()).hexdigest() for p in maps}
    out["map_sums"] = {}
    for p in maps:
        m = np.load(p)
        out["map_sums"][p.name] = [float(np.sum(m, dtype=np.float64)), int(np.count_nonzero(m >= 0.5))]
    records = {}
    for p in sorted((folder / "frames").glob("*.json")):
        stats = json.loads(p.read_text()).get("stats", {})
        records[p.stem] = {k: stats.get(k) for k in COUNTS}
    out["frames"] = records
    return out


def record() -> None:
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        result = {name: digest(run_scenario(name, Path(tmp))) for name in scenarios()}
    GOLDEN.write_text(json.dumps(result, indent=1, sort_keys=True) + "\n")
    print(f"wrote {GOLDEN} ({len(result)} runs)")


if __name__ == "__main__":
    sys.path.insert(0, str(ROOT))
    record()
