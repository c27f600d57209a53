"""Mutation testing as a habit (issue 63): mutmut on a module with its related tests, the score
printed per module. mutmut wants its settings in pyproject.toml and writes a `mutants/` copy of
the tree beside it, so each module runs in a scratch clone of the repository (HEAD, or
`--commit`), not in this checkout.

    pip install -e ".[mutation]"
    python -m bench.mutation evaluate tracking [--commit SHA] [--work /tmp/dpom-mutation]
        [--output runs/mutation/scores.json] [--keyword EXPR]

Each mutant (an operator, a constant, a call's argument changed; mutmut 3) is run against the
module's related tests (MODULES) that cover its function; it is killed when one fails, and
survives when all pass. Score = killed / (killed + survived). The mutants that survive are
listed (`mutmut show NAME` in the clone shows one). A run takes a few minutes per thousand
mutants on two cores.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

# module -> (its file, the pytest arguments that select the tests about it)
MODULES = {
    "evaluate": ("dpom_warp/evaluate.py", ["tests/test_detect_eval.py", "tests/test_eval.py"]),
    "tracking": ("dpom_warp/tracking.py", ["tests/test_tracking.py"]),
    "model": ("dpom_warp/model.py", ["tests/test_model_cases.py"]),
    # the config's value types and checks, with the corpus of bad configs and every stated limit
    "config": ("dpom_warp/values.py", ["tests/test_errors.py", "-k", "bad_config or yaml_syntax or limit"]),
    "zones": ("dpom_warp/zones.py", ["tests/test_zones.py"]),
    "drift": ("dpom_warp/drift.py", ["tests/test_drift.py"]),
}
KILLED, SURVIVED = 1, 0  # mutmut 3's exit codes of a mutant's test run (its .meta files)


def clone(commit: str, work: Path, module: str, keyword: str | None = None) -> Path:
    """A scratch clone at `commit` with mutmut's settings for `module` (and ../shared beside it);
    `keyword`: only its tests that pytest's -k selects."""
    path, tests = MODULES[module]
    tests = tests + ["-k", keyword] if keyword else tests
    where = work / f"{module}-{commit[:10]}"
    if where.exists():
        subprocess.run(["rm", "-rf", str(where)], check=True)
    work.mkdir(parents=True, exist_ok=True)
    subprocess.run(["git", "clone", "-q", str(ROOT), str(where)], check=True)
    subprocess.run(["git", "-C", str(where), "checkout", "-q", commit], check=True)
    # the clone's own kernels (the installed package maps dpom_warp.kernels to this checkout's)
    (where / "dpom_warp" / "kernels").symlink_to("../kernels")
    shared = ROOT.parent / "shared"
    if shared.exists() and not (where.parent / "shared").exists():
        (where.parent / "shared").symlink_to(shared)
    with open(where / "pyproject.toml", "a") as f:
        f.write("\n[tool.mutmut]\n"
                f"source_paths = [\"{path}\"]\n"
                f"pytest_add_cli_args_test_selection = {json.dumps(tests)}\n"
                # one process: mutmut runs pytest in its own process and reads its own plugin's stats
                "pytest_add_cli_args = [\"-n\", \"0\"]\n"
                "also_copy = [\"dpom_warp\", \"kernels\", \"configs\", \"bench\", \"tests\", \"README.md\", \"docs\"]\n")
    # the tests find ../shared from the mutants/ copy too
    if shared.exists():
        (where / "shared").symlink_to(shared)
    return where


def score(where: Path, module: str) -> dict:
    """Killed, survived and the survivors' names from the clone's mutants/*.meta."""
    path, _ = MODULES[module]
    meta = json.loads((where / "mutants" / f"{path}.meta").read_text())
    codes = meta["exit_code_by_key"]
    count = Counter(codes.values())
    killed, survived = count.get(KILLED, 0), count.get(SURVIVED, 0)
    return {"module": module, "file": path, "mutants": len(codes), "killed": killed, "survived": survived,
            "other": len(codes) - killed - survived,
            "score": round(killed / max(1, killed + survived), 4),
            "survivors": sorted(k for k, v in codes.items() if v == SURVIVED)}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("modules", nargs="+", choices=list(MODULES))
    ap.add_argument("--commit", default="HEAD", help="the commit whose tests are scored (default: HEAD)")
    ap.add_argument("--work", default="/tmp/dpom-mutation", help="where the scratch clones go")
    ap.add_argument("--output", default=None, help="a JSON file for the scores (and the survivors)")
    ap.add_argument("--keyword", default=None, help="only the module's tests pytest -k selects (drift: by_hand, "
                                                    "the tests that render no scene)")
    a = ap.parse_args()
    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", a.commit], check=True, capture_output=True,
                            text=True).stdout.strip()
    results = []
    for module in a.modules:
        where = clone(commit, Path(a.work), module, a.keyword)
        env = dict(os.environ, WARP_CACHE_PATH=str(where / ".cache" / "warp"))
        t = time.perf_counter()
        run = subprocess.run([sys.executable, "-m", "mutmut", "run"], cwd=where, env=env, capture_output=True,
                             text=True)
        if run.returncode != 0:
            raise SystemExit(f"mutmut on {module} failed (exit {run.returncode}): {run.stdout[-2000:]}{run.stderr[-2000:]}")
        r = score(where, module) | {"commit": commit[:10], "seconds": round(time.perf_counter() - t),
                                    "keyword": a.keyword}
        results.append(r)
        print(f"{module} ({r['file']}) at {r['commit']}: {r['killed']} of {r['killed'] + r['survived']} mutants "
              f"killed, score {r['score']:.3f} ({r['other']} not run or timed out; {r['seconds']} s)", flush=True)
    if a.output:
        Path(a.output).parent.mkdir(parents=True, exist_ok=True)
        Path(a.output).write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
