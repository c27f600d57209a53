"""`--ray` against a Ray cluster started as users start it (`ray start --head` in a subprocess
on a free port, stopped at the end), whose workers cannot open the frame files (so the frames
must travel as bytes): `--ray ADDRESS`, `$RAY_ADDRESS` and `--ray auto` join it and give a
plain run's files, `--workers N` sets the actor count; a bad later config stops the call before
any frame is sent; a frame that takes down every actor it reaches is skipped (fatal with
--strict); SIGTERM stops the run and frees the cluster."""

import json
import shutil
import socket
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

from dpom_warp.cli import main

from test_cli import small_config
from test_ray import assert_same_files

RAY = Path(sys.executable).parent / "ray"
CPUS = 3  # the cluster's logical CPUs: one actor each
POISON = "/poison/0002.png"  # a frame that ends the process of any actor given it


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory, scene):
    """A head node with 3 CPUs on a free port and localhost, its own temporary folder, no token
    authentication (a token a user made for their own cluster must not leak in), frames slowed
    by half a second and frame poison/0002.png fatal to its actor's process (tests/slow.py);
    stopped afterwards."""
    import tempfile

    tmp = Path(tempfile.mkdtemp(prefix="rc", dir="/tmp"))  # Ray's socket paths must stay short
    port = free_port()
    from slow import slow_env

    # the cluster's workers infer each chunk half a second slower: a signal sent after the
    # first frame is written always lands while the run goes on
    env = {**slow_env(tmp, 0.5), "RAY_TMPDIR": str(tmp / "ray"), "RAY_AUTH_MODE": "disabled",
           "DPOM_TEST_NO_READ": str(scene[0] / "scene"),  # its workers cannot read the frames
           "DPOM_TEST_CRASH": POISON}
    env.pop("RAY_ADDRESS", None)
    start = subprocess.run([str(RAY), "start", "--head", f"--port={port}", "--node-ip-address=127.0.0.1",
                            f"--num-cpus={CPUS}", "--num-gpus=0",
                            "--include-dashboard=false", "--disable-usage-stats"],
                           capture_output=True, text=True, timeout=180, env=env)
    assert start.returncode == 0, start.stderr[-2000:]
    try:
        yield f"127.0.0.1:{port}", env
    finally:
        stop_cluster(str(tmp))
        shutil.rmtree(tmp, ignore_errors=True)


def stop_cluster(folder: str, timeout: float = 30.0) -> None:
    """Kill this cluster's processes: those naming its temporary `folder` (GCS, raylet, monitors)
    and their descendants (the agents and actors, whose titles are Ray's own). Not `ray stop
    --force`, which kills every Ray process on the machine: a local instance of test_ray's in the
    other xdist worker lost its raylet to it mid-test."""
    import os
    import signal
    import time

    from test_ray import instance_processes

    def family() -> list[int]:
        children: dict = {}
        for pid in filter(str.isdigit, os.listdir("/proc")):
            try:
                with open(f"/proc/{pid}/stat") as f:
                    state, ppid = f.read().rsplit(")", 1)[1].split()[:2]
            except (OSError, ValueError):
                continue
            if state != "Z":  # a zombie is gone already
                children.setdefault(int(ppid), []).append(int(pid))
        todo, found = instance_processes(folder), set()
        while todo:
            pid = todo.pop()
            if pid not in found:
                found.add(pid)
                todo += children.get(pid, [])
        return sorted(found)

    deadline = time.time() + timeout
    while (pids := family()) and time.time() < deadline:
        for pid in pids:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        time.sleep(0.2)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("rayscene")
    path = small_config(tmp, frames=6)
    assert main(["run", str(path), "--no-progress", "--output", str(tmp / "plain")]) == 0
    return tmp, path


def dpom(args, env, timeout=600):
    """dpom-warp in a subprocess as a driver: it reads the frames (the cluster's workers cannot)."""
    env = {k: v for k, v in env.items() if k != "DPOM_TEST_NO_READ"}
    return subprocess.run([sys.executable, "-m", "dpom_warp.cli", *args], capture_output=True, text=True,
                          timeout=timeout, env=env)


def test_the_cluster_workers_cannot_read_the_frames(cluster, scene):
    """What makes the runs here prove that frames travel as bytes: a task on the cluster that
    opens a frame file is refused."""
    import ray

    address, env = cluster
    frame = sorted((scene[0] / "scene" / "frames").glob("*.png"))[0]
    assert not ray.is_initialized()
    ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        @ray.remote
        def read(path):
            try:
                with open(path, "rb") as f:
                    return len(f.read())
            except PermissionError as e:
                return str(e)

        assert "this node has no access to the frames" in ray.get(read.remote(str(frame)), timeout=120)
    finally:
        ray.shutdown()


def test_ray_address_env_and_auto_join_the_cluster(cluster, scene, tmp_path):
    address, env = cluster
    tmp, path = scene
    for name, args, extra_env in (("address", ["--ray", address], {}),
                                  ("auto", ["--ray", "auto"], {}),
                                  ("env, workers", ["--ray", "--workers", "2"], {"RAY_ADDRESS": address})):
        out = tmp_path / name.replace(", ", "_")
        proc = dpom(["run", str(path), "--no-progress", *args, "--output", str(out)], {**env, **extra_env})
        assert proc.returncode == 0, (name, proc.stderr[-2000:])
        assert_same_files(tmp / "plain", out, 6)
        runner = json.loads((out / "summary.json").read_text())["runner"]
        actors = 2 if "workers" in name else CPUS  # --workers N, else one per CPU of the cluster
        assert runner["kind"] == "ray" and runner["actors"] == actors, name
        assert f"ray: {actors} actors (one CPU each)" in proc.stdout, name
        assert set(runner["frames_per_worker"]) <= {f"actor {i}" for i in range(actors)}, name
        assert runner["cluster"] != "a local Ray instance", name  # it joined the cluster


def test_a_bad_later_config_stops_the_call_before_any_frame(cluster, scene, tmp_path, capsys):
    address, env = cluster
    tmp, path = scene
    bad = tmp_path / "bad.yaml"
    cfg = yaml.safe_load(path.read_text())
    cfg["model"]["prior"] = 2.0
    bad.write_text(yaml.safe_dump(cfg))
    proc = dpom(["run", str(path), str(bad), "--no-progress", "--ray", address, "--output", str(tmp_path / "o")],
                env)
    assert proc.returncode == 2 and "model.prior" in proc.stderr and "\n" not in proc.stderr.strip()
    assert not (tmp_path / "o").exists()  # not even the first config's run started


def test_a_frame_that_takes_down_its_actor_twice_is_skipped(cluster, scene, tmp_path):
    """No actor restarts; frame 0002 ends the process of any actor given it (tests/slow.py). The
    first actor's frames are sent again one by one, each first on an idle actor: 0002 takes
    down a second actor and is skipped with its reason, the frame queued behind it is kept,
    and the third actor does the rest (the plain run's detections but 0002's). With --strict
    that frame is fatal: one line, exit code 2, nothing but finished frames left."""
    from dpom_warp.cluster import MAX_LOSSES

    address, env = cluster
    tmp, path = scene
    shutil.copytree(tmp / "scene" / "frames", tmp_path / "poison")
    cfg = yaml.safe_load(path.read_text())
    del cfg["synthetic"]
    cfg["input"]["frames"] = f"{tmp_path / 'poison'}/*.png"
    config = tmp_path / "poison.yaml"
    config.write_text(yaml.safe_dump(cfg))
    env = {**env, "DPOM_TEST_RESTARTS": "0"}  # the driver's actors are not restarted
    out = tmp_path / "out"
    proc = dpom(["run", str(config), "--no-progress", "--ray", address, "--output", str(out)], env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert proc.stdout.count("died (") == 2 and "its frames go to the other actors" in proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["skipped"] == [{"frame": "0002.png", "reason": f"{tmp_path}{POISON}: the actor inferring it "
                                   f"died {MAX_LOSSES} times (killed, or out of memory)"}]
    assert sorted(p.name for p in (out / "maps").iterdir()) == [f"000{i}.npy" for i in (0, 1, 3, 4, 5)]
    plain = (tmp / "plain" / "detections.csv").read_text().splitlines()
    assert (out / "detections.csv").read_text().splitlines() == [r for r in plain if not r.startswith("0002.png,")]
    assert summary["runner"]["frames_resent"] >= 1  # 0002 and what was queued behind it

    strict = tmp_path / "strict"
    proc = dpom(["run", str(config), "--no-progress", "--ray", address, "--strict", "--output", str(strict)], env)
    err = proc.stderr.strip()
    assert proc.returncode == 2 and err.endswith(f"{POISON}: the actor inferring it died 2 times (killed, or out "
                                                 f"of memory)") and "\n" not in err, err[-2000:]
    assert not (strict / "detections.csv").exists() and not [p for p in strict.rglob(".*") if p.is_file()]


def test_sigterm_on_a_ray_run_stops_it_and_its_actors(cluster, scene, tmp_path):
    """SIGTERM on a --ray run: exit 130 (its own handler, not Ray's), whole files, its actors
    gone from the cluster (every CPU free again, as Ray reports it); --resume finishes it to
    the plain run's files."""
    import signal
    import time

    import ray

    address, env = cluster
    tmp, path = scene
    out = tmp_path / "ray"
    driver_env = {k: v for k, v in env.items() if k not in ("PYTHONPATH", "DPOM_TEST_NO_READ")}
    proc = subprocess.Popen([sys.executable, "-m", "dpom_warp.cli", "run", str(path), "--no-progress", "--ray",
                             address, "--output", str(out)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, env=driver_env)
    deadline = time.time() + 180
    # a finished record (glob("*.json") also matches a record being written: .NAME.json.tmp-*.json)
    while not list((out / "frames").glob("[!.]*.json")) and time.time() < deadline and proc.poll() is None:
        time.sleep(0.01)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 130, err[-2000:]
    assert "continue with --resume" in err
    assert not [p for p in out.rglob(".*") if p.is_file()]
    assert 1 <= len(list((out / "frames").glob("*.json"))) < 6
    ray.init(address=address, include_dashboard=False, log_to_driver=False)
    try:
        deadline = time.time() + 30
        while ray.available_resources().get("CPU", 0) < CPUS and time.time() < deadline:
            time.sleep(0.2)
        assert ray.available_resources().get("CPU", 0) == CPUS  # the actors went with the run
    finally:
        ray.shutdown()
    proc = dpom(["run", str(path), "--no-progress", "--ray", address, "--resume", "--output", str(out)], env)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert_same_files(tmp / "plain", out, 6)
