"""`dpom-warp run ... --ray` on a real local Ray instance (ray.init(num_cpus=2)): the same files
as a plain run, actors killed mid-run, several configs in one call, Ctrl-C and --resume."""

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
import yaml

import ray

from dpom_warp import cluster
from dpom_warp.cli import main

from test_cli import small_config


@pytest.fixture(scope="module")
def local_ray():
    """One local Ray instance for the module (2 CPUs, no GPU: the 2-core CI machine's size)."""
    ray.init(num_cpus=2, num_gpus=0, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """A rendered sequence of 12 frames, its config and a plain run of it ('plain')."""
    tmp = tmp_path_factory.mktemp("ray")
    path = small_config(tmp, frames=12)
    assert main(["run", str(path), "--no-progress", "--output", str(tmp / "plain")]) == 0
    return tmp, path


def config(tmp_path, scene_path, name="config", **changes):
    """A copy of the scene's config (its frames rendered already), with `changes` applied to
    its sections ({'detection': {'threshold': 0.6}})."""
    cfg = yaml.safe_load(Path(scene_path).read_text())
    del cfg["synthetic"]
    cfg["output"]["dir"] = str(tmp_path / f"out-{name}")
    for section, values in changes.items():
        cfg[section].update(values)
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(cfg))
    return path


def assert_same_files(a: Path, b: Path, frames: int):
    for name in ("detections.csv", "tracks.csv", "track_table.csv"):
        assert (a / name).read_bytes() == (b / name).read_bytes(), name
    for folder, n in (("maps", frames), ("images", frames)):
        names = sorted(p.name for p in (a / folder).iterdir())
        assert len(names) == n and names == sorted(p.name for p in (b / folder).iterdir())
        for name in names:
            assert (a / folder / name).read_bytes() == (b / folder / name).read_bytes(), f"{folder}/{name}"
    assert json.load(open(a / "summary.json"))["scores"] == json.load(open(b / "summary.json"))["scores"]


@pytest.fixture
def actor_pids(monkeypatch):
    """A function giving the PIDs of this test's FrameActor processes that are inferring now:
    the PIDs Ray reported for the run's actors (cluster.ActorPool, recorded as it learns them),
    busy when Ray titles the process ray::FrameActor.process. No other process is touched."""
    pools = []
    real = cluster.ActorPool.__init__

    def recorded(self, *args, **kwargs):
        real(self, *args, **kwargs)
        pools.append(self)

    monkeypatch.setattr(cluster.ActorPool, "__init__", recorded)

    def busy() -> list[int]:
        pids = []
        for pool in list(pools):
            try:
                known = [pid for group in list(pool.pids.values()) for pid in group]
            except RuntimeError:  # the driver added an actor meanwhile: the next look sees it
                continue
            for pid in known:
                try:
                    with open(f"/proc/{pid}/cmdline", "rb") as f:
                        if f.read().startswith(b"ray::FrameActor.process"):
                            pids.append(pid)
                except OSError:
                    pass
        return pids

    return busy


def instance_processes(folder: str) -> list[int]:
    """PIDs of the processes of the Ray instance whose temporary folder is `folder` (its GCS
    server, raylet and workers name their session folder under it on their command line)."""
    pids = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            with open(f"/proc/{pid}/cmdline", "rb") as f:
                if folder.encode() in f.read():
                    pids.append(int(pid))
        except OSError:
            pass
    return pids


def test_ray_gives_the_plain_run_files(tmp_path, local_ray, scene):
    tmp, path = scene
    assert main(["run", str(path), "--no-progress", "--ray", "--output", str(tmp_path / "ray")]) == 0
    assert_same_files(tmp / "plain", tmp_path / "ray", 12)
    runner = json.load(open(tmp_path / "ray" / "summary.json"))["runner"]
    assert runner["kind"] == "ray" and runner["actors"] == 2 and runner["actor_restarts"] == 0
    assert sorted(runner["frames_per_worker"]) == ["actor 0", "actor 1"]
    assert sum(runner["frames_per_worker"].values()) == 12 and runner["frames_resumed"] == 0
    plain = json.load(open(tmp / "plain" / "summary.json"))["runner"]
    assert plain["kind"] == "one process" and plain["frames_per_worker"] == {"main": 12}
    assert plain["frames_resumed"] == 0 and runner["frames_per_s"] > 0 and plain["frames_per_s"] > 0
    assert 0 < runner["driver_s_per_frame"] < runner["frames_wall_s"] / 12


@pytest.mark.parametrize("restarts", [cluster.ACTOR_RESTARTS, 0])
def test_killed_actor_loses_no_frame(tmp_path, local_ray, scene, monkeypatch, capsys, restarts, actor_pids):
    """An actor process killed while it infers: Ray restarts it and retries its calls, or
    (no restarts left) its frames go to the other actor; every frame is written once."""
    tmp, path = scene
    monkeypatch.setattr(cluster, "ACTOR_RESTARTS", restarts)
    writes = []
    from dpom_warp.loop import FrameLoop

    real = FrameLoop.write

    def counted(loop, done):
        writes.append(done.name)
        return real(loop, done)

    monkeypatch.setattr(FrameLoop, "write", counted)
    killed = []

    def kill_first_busy_actor():
        deadline = time.time() + 120
        while not killed and time.time() < deadline:
            for pid in actor_pids():
                os.kill(pid, signal.SIGKILL)
                killed.append(pid)
                break
            time.sleep(0.002)

    killer = threading.Thread(target=kill_first_busy_actor)
    killer.start()
    try:
        assert main(["run", str(path), "--no-progress", "--ray", "--output", str(tmp_path / "ray")]) == 0
    finally:
        killer.join()
    assert killed
    assert sorted(writes) == sorted(f"{i:04d}.png" for i in range(12))  # each frame once
    assert_same_files(tmp / "plain", tmp_path / "ray", 12)
    runner = json.load(open(tmp_path / "ray" / "summary.json"))["runner"]
    out = capsys.readouterr().out
    if restarts:
        assert runner["actor_restarts"] == 1 and "was restarted" in out
    else:
        assert runner["frames_resent"] >= 1 and "its frames go to the other actors" in out
        assert runner["actor_restarts"] == 0


def test_two_configs_in_one_call(tmp_path, local_ray, scene):
    """Two runs share the actors, each to its own folder under --output, each with the files
    of its own plain run."""
    tmp, path = scene
    a = config(tmp_path, path, "a")
    b = config(tmp_path, path, "b", detection={"threshold": 0.7}, grid={"x": [-2.0, 2.0, 0.25]})
    assert main(["run", str(b), "--no-progress", "--output", str(tmp_path / "plain-b")]) == 0
    assert main(["run", str(a), str(b), "--no-progress", "--ray", "--output", str(tmp_path / "both")]) == 0
    assert_same_files(tmp / "plain", tmp_path / "both" / "a", 12)
    assert_same_files(tmp_path / "plain-b", tmp_path / "both" / "b", 12)
    assert (tmp_path / "both" / "a" / "detections.csv").read_bytes() != \
        (tmp_path / "both" / "b" / "detections.csv").read_bytes()
    for name in "ab":
        runner = json.load(open(tmp_path / "both" / name / "summary.json"))["runner"]
        assert runner["runs"] == 2 and sum(runner["frames_per_worker"].values()) == 12
    # without --ray the runs go one after the other, to the same files
    assert main(["run", str(a), str(b), "--no-progress", "--output", str(tmp_path / "seq")]) == 0
    assert_same_files(tmp_path / "both" / "a", tmp_path / "seq" / "a", 12)
    assert_same_files(tmp_path / "both" / "b", tmp_path / "seq" / "b", 12)


def test_ctrl_c_then_resume_on_ray(tmp_path, local_ray, scene):
    """Ctrl-C stops a --ray run (its own local Ray instance) with exit code 130 and whole
    files, and that instance is stopped (no process of it left); --resume on Ray finishes it
    to the plain run's files."""
    import shutil
    import tempfile

    tmp, path = scene
    out = tmp_path / "ray"
    from slow import slow_env

    env = slow_env(tmp_path, 1.0)  # each frame a second longer: the signal comes before the end
    env.pop("RAY_ADDRESS", None)
    ray_tmp = tempfile.mkdtemp(prefix="rl", dir="/tmp")  # the instance's own folder (short: socket paths)
    env["RAY_TMPDIR"] = ray_tmp
    proc = subprocess.Popen([sys.executable, "-m", "dpom_warp.cli", "run", str(path), "--no-progress",
                             "--ray", "--output", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env)
    deadline = time.time() + 180
    # a finished record (glob("*.json") also matches a record being written: .NAME.json.tmp-*.json)
    while not list((out / "frames").glob("[!.]*.json")) and time.time() < deadline and proc.poll() is None:
        time.sleep(0.01)
    assert instance_processes(ray_tmp)  # what the check below looks for is there while it runs
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    done = len(list((out / "frames").glob("*.json")))
    assert proc.returncode == 130, err
    assert "continue with --resume" in err
    assert not [p for p in out.rglob(".*") if p.is_file()]  # no temporary files left
    assert 1 <= done < 12 and not (out / "detections.csv").exists()
    deadline = time.time() + 30
    while instance_processes(ray_tmp) and time.time() < deadline:
        time.sleep(0.2)
    assert not instance_processes(ray_tmp)  # the local instance went with the run
    shutil.rmtree(ray_tmp, ignore_errors=True)
    assert main(["run", str(path), "--no-progress", "--ray", "--resume", "--output", str(out)]) == 0
    assert_same_files(tmp / "plain", out, 12)
    runner = json.load(open(out / "summary.json"))["runner"]
    assert runner["frames_resumed"] == done and sum(runner["frames_per_worker"].values()) == 12 - done


def test_ray_errors_are_one_line(tmp_path, local_ray, scene, capsys, monkeypatch):
    tmp, path = scene
    cases = [
        (["--ray", "--workers", "3"], "--workers: expected at most the cluster's 2 CPUs (one actor each), found 3"),
        (["--ray", "--device", "cuda"], "but the Ray cluster has no GPU; expected a cluster with GPUs, or device: cpu"),
        (["--ray", "--device", "gpu"], "--device: expected auto, cpu, cuda or cuda:N, found 'gpu'"),
    ]
    for args, message in cases:
        out = tmp_path / "out"
        assert main(["run", str(path), "--no-progress", "--output", str(out)] + args) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1
        assert not out.exists()  # nothing written
    a = config(tmp_path, path, "a")
    same = config(tmp_path, path, "same")
    yaml_a = yaml.safe_load(a.read_text())
    yaml_a["output"]["dir"] = yaml.safe_load(same.read_text())["output"]["dir"]
    a.write_text(yaml.safe_dump(yaml_a))
    assert main(["run", str(a), str(same), "--no-progress", "--ray"]) == 2
    assert "both write to" in capsys.readouterr().err
    gpu = config(tmp_path, path, "gpu")
    yaml_gpu = yaml.safe_load(gpu.read_text())
    yaml_gpu["device"] = "cuda"
    gpu.write_text(yaml.safe_dump(yaml_gpu))
    assert main(["run", str(path), str(gpu), "--no-progress", "--ray", "--output", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert f"device: {path} asks for cpu and {gpu} for cuda; expected one kind of device" in err
    assert not (tmp_path / "x").exists()
    monkeypatch.setitem(sys.modules, "ray", None)  # Ray not installed
    assert main(["run", str(path), "--no-progress", "--ray", "--output", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "--ray: Ray is not installed" in err and "pip install 'dpom-warp[ray]'" in err


def test_actor_that_cannot_start_is_one_line_and_writes_nothing(tmp_path, local_ray, scene, capsys,
                                                               monkeypatch):
    """Every node must run the driver's dpom-warp: an actor of another version does not start."""
    tmp, path = scene
    monkeypatch.setattr(cluster, "package_version", lambda: "0.0.0")
    out = tmp_path / "out"
    assert main(["run", str(path), "--no-progress", "--ray", "--output", str(out)]) == 1
    err = capsys.readouterr().err
    assert "--ray: actor" in err and "could not start" in err and "0.0.0 on the driver" in err
    assert err.count("\n") == 1 and not out.exists()


def test_every_actor_dead_is_one_line_and_keeps_finished_frames(tmp_path, local_ray, scene, monkeypatch,
                                                                capsys, actor_pids):
    """No restarts and every actor process killed as soon as it infers: the call ends with one
    line (exit 1), the frames finished before are whole, and --resume (with actors that live)
    finishes the run to the plain run's files."""
    tmp, path = scene
    monkeypatch.setattr(cluster, "ACTOR_RESTARTS", 0)
    stop, killed = threading.Event(), []

    def kill_every_busy_actor():
        while not stop.is_set():
            for pid in actor_pids():
                try:
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
                except ProcessLookupError:
                    pass
            time.sleep(0.002)

    killer = threading.Thread(target=kill_every_busy_actor)
    killer.start()
    out = tmp_path / "ray"
    try:
        code = main(["run", str(path), "--no-progress", "--ray", "--output", str(out)])
    finally:
        stop.set()
        killer.join()
    err = capsys.readouterr().err.strip()
    assert code == 1 and len(set(killed)) >= 2
    assert err.splitlines()[-1] == ("dpom-warp: error: --ray: every actor has died; finished frames are kept, "
                                    "continue with --resume")
    assert not (out / "detections.csv").exists()
    monkeypatch.setattr(cluster, "ACTOR_RESTARTS", 3)
    assert main(["run", str(path), "--no-progress", "--ray", "--resume", "--output", str(out)]) == 0
    assert_same_files(tmp / "plain", out, 12)
