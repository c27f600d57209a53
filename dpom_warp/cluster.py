"""`dpom-warp run CONFIG... --ray [ADDRESS]`: the frames of one or several runs on a Ray cluster.

Every run is set up here, in the driver, as in a plain run (pipeline.plan_run: frames checked,
pose fitted, background estimated, kernels compiled); then Ray actors infer the frames. Each
actor (one CPU, or one GPU when the runs' device is CUDA) builds a run's engine once, from
the run's WorkerSpec and the driver's compiled kernels, and keeps the engines of the last two
runs it served, so the frames of several runs share the actors. The driver writes every
output, as a plain run does (its FrameLoop, loop.py), so the files are the same.

Frames travel as the bytes of their files, read by the driver just before they are sent: the
nodes need no shared disk, a 16-bit PNG is 3-5x smaller than the float32 array it decodes
to, and decoding happens on the actors. Results come back as the map, the picture's PNG
bytes (drawn on the actor: the driver only writes files) and the frame's record.

Faults: an actor whose process dies (killed, out of memory, its node lost) is restarted by
Ray, which retries its unfinished calls on the new process (max_restarts, max_task_retries);
an actor that is gone for good has its frames sent to the others, each alone to an actor with
nothing in flight (so that it is the first that actor infers). A frame is written once, when
its result arrives; a frame that has taken down its actor for good MAX_LOSSES (2) times, the
second time as the first frame an idle actor was given, is skipped with that reason. An actor
that cannot start leaves its share to the others. Ctrl-C or SIGTERM kills the actors;
finished frames are kept for --resume.
"""

from __future__ import annotations

import collections
import contextlib
import dataclasses
import os
import signal
import time

from .config import ConfigError
from .io import InputError, WorkerError
from .worker import FrameWorker, install_kernel_cache, kernel_cache

INSTALL = "pip install 'dpom-warp[ray]'"
IN_FLIGHT = 2  # calls queued per actor: the next frames wait on the actor, not on the driver
ENGINES_KEPT = 2  # engines an actor keeps (runs it served last)
MAX_LOSSES = 2  # a frame whose actor died for good this many times is skipped
ACTOR_RESTARTS = 3  # per actor; Ray retries the calls it had on the restarted process


def import_ray():
    try:
        import ray
    except ImportError:
        raise ConfigError(f"--ray: Ray is not installed; expected it, install it with {INSTALL}") from None
    return ray


@contextlib.contextmanager
def connect(address: str | None):
    """Ray for this call: the instance this process runs already (tests, notebooks), else the
    cluster at `address` or $RAY_ADDRESS, else a new local instance sized to this machine
    (stopped at the end). Yields a description of it."""
    ray = import_ray()
    if ray.is_initialized():
        yield "the running Ray instance"
        return
    address = address or os.environ.get("RAY_ADDRESS") or None
    if address and address not in ("auto", "local"):
        reachable(address)
    handler = signal.getsignal(signal.SIGTERM)
    import logging

    try:
        ray.init(address=address or "local", include_dashboard=False, log_to_driver=False,
                 logging_level=logging.WARNING)
    except (ConnectionError, ValueError, RuntimeError) as e:
        first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        where = f"join a Ray cluster at {address}" if address else "start a local Ray instance"
        raise ConfigError(f"--ray: cannot {where}: {first}") from None
    signal.signal(signal.SIGTERM, handler)  # ray.init replaces it; ours unwinds like Ctrl-C
    try:
        yield ("a local Ray instance" if not address else "the Ray cluster `ray start` runs here"
               if address == "auto" else f"the Ray cluster at {address}")
    finally:
        ray.shutdown()


def reachable(address: str, timeout: float = 3.0) -> None:
    """A cluster address (HOST:PORT, or ray://HOST:PORT for Ray Client) that answers a TCP
    connection; else a one-line error at once (Ray itself retries for minutes)."""
    import socket

    hostport = address.split("://", 1)[-1]
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise ConfigError(f"--ray: expected HOST:PORT (the address `ray start --head` prints), auto, "
                          f"or nothing for a local instance; found {address!r}")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout):
            pass
    except OSError as e:
        why = e.strerror or type(e).__name__
        raise ConfigError(f"--ray: cannot join a Ray cluster at {address}: nothing answers there ({why}); "
                          f"expected the head's address, e.g. HOST:6379 from `ray start --head`") from None


def package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("dpom-warp")
    except PackageNotFoundError:
        return "unknown"


class FrameActor:
    """A Ray actor's state (made remote by actor_class): the engines of the runs it serves."""

    def __init__(self, index: int, device: str, version: str):
        here = package_version()
        if here != version:
            raise RuntimeError(f"dpom-warp {here} on this node, {version} on the driver; "
                               f"expected the same version on every node")
        self.index, self.device = index, device
        self.workers: collections.OrderedDict = collections.OrderedDict()

    def info(self) -> dict:
        import ray

        node = ray.get_runtime_context().get_node_id()
        return {"pid": os.getpid(), "node": f"{ray.util.get_node_ip_address()} ({node[:8]})"}

    def process(self, run: int, refs: list, items: list):
        """FrameWorker.process of run `run`'s frames; `refs` = [the run's WorkerSpec, the
        driver's compiled kernels] in the object store (in a list: fetched only when this
        actor first serves the run; the kernels before Warp starts in this process)."""
        import ray

        worker = self.workers.get(run)
        if worker is None:
            spec_ref, cache_ref = refs
            install_kernel_cache(ray.get(cache_ref))  # a no-op once Warp has started
            spec = dataclasses.replace(ray.get(spec_ref), device=self.device)
            worker = self.workers[run] = FrameWorker(spec, name=f"actor {self.index}")
            while len(self.workers) > ENGINES_KEPT:
                self.workers.popitem(last=False)
        self.workers.move_to_end(run)
        return self.info(), worker.process(items)


def actor_class(ray, gpu: bool):
    options = {"num_cpus": 1, "num_gpus": 1 if gpu else 0, "max_restarts": ACTOR_RESTARTS,
               "max_task_retries": ACTOR_RESTARTS}
    return ray.remote(**options)(FrameActor)


def actor_kind(ray, devices: list[tuple[str, str]]) -> bool:
    """True for GPU actors. `devices`: (config file, its device setting) of every run."""
    kinds = {d.split(":")[0] for _, d in devices} - {"auto"}
    if len(kinds) > 1:
        (a, da), (b, db) = [next((n, d) for n, d in devices if d.startswith(k)) for k in sorted(kinds)]
        raise ConfigError(f"device: {a} asks for {da} and {b} for {db}; expected one kind of "
                          f"device for the runs of one --ray call")
    gpus = ray.cluster_resources().get("GPU", 0)
    if kinds == {"cuda"}:
        if gpus < 1:
            source, device = next((n, d) for n, d in devices if d.startswith("cuda"))
            raise ConfigError(f"device: {device} (in {source}), but the Ray cluster has no GPU; "
                              f"expected a cluster with GPUs, or device: cpu")
        return True
    return kinds != {"cpu"} and gpus >= 1


def actor_count(ray, gpu: bool, wanted: int | None) -> int:
    """One actor per GPU (gpu) or per CPU of the cluster, or `wanted` (--workers) if fewer."""
    resource = "GPU" if gpu else "CPU"
    have = int(ray.cluster_resources().get(resource, 0))
    if wanted is not None and wanted > have:
        raise ConfigError(f"--workers: expected at most the cluster's {have} {resource}s "
                          f"(one actor each), found {wanted}")
    if have < 1:
        raise ConfigError(f"--ray: the cluster has no {resource}; expected at least one")
    return wanted or have


def run_on_ray(plans: list, sources: list[str], devices: list[str], address: str | None,
               workers: int | None, overwrite: bool, resume: bool, progress: bool,
               log=print) -> list[dict]:
    """Infer the frames of every plan (pipeline.RunPlan, made with parallel=True) on Ray
    actors, each run writing to its own output; returns their summaries, in order.
    `sources` names each run's config and `devices` gives its device setting (for errors);
    `workers`: the number of actors (None: one per CPU, or per GPU, of the cluster).
    Nothing is written before the first actor has started."""
    from .outputs import remove_temporaries
    from .pipeline import abandon_if_empty, finish_run, open_output, progress_bar

    with connect(address) as where:
        ray = import_ray()
        gpu = actor_kind(ray, list(zip(sources, devices)))
        n = actor_count(ray, gpu, workers)
        nodes = sum(1 for node in ray.nodes() if node.get("Alive"))
        device = "cuda:0" if gpu else "cpu"
        cls = actor_class(ray, gpu)
        pool = ActorPool(ray, [cls.remote(i, device, package_version()) for i in range(n)])
        try:
            pool.first_started(log)
            for p in plans:
                p.device = f"{device} (Ray actors)"
                open_output(p, overwrite, resume, log)
            log(f"ray: {n} actors ({'one GPU' if gpu else 'one CPU'} each) on {where} "
                f"({nodes} node{'s' if nodes > 1 else ''})")
            cache = ray.put(kernel_cache())
            refs = [[ray.put(p.spec), cache] for p in plans]
            jobs = [(run, chunk) for run, p in enumerate(plans) for chunk in p.chunks()]
            t0 = time.perf_counter()
            frames = sum(len(c) for _, c in jobs)
            outcomes = progress_bar(pool.outcomes(refs, jobs, log), frames, "dpom ray", progress)
            try:
                for run, name, output, error in outcomes:
                    plans[run].loop.accept(name, output, error)
            except (InputError, ConfigError):
                for p in plans:
                    abandon_if_empty(p)  # --strict before any frame: nothing left behind
                raise
            except KeyboardInterrupt:  # the frames are written here, in this thread: none in flight
                for p in plans:
                    remove_temporaries(p.out)
                raise
            wall = time.perf_counter() - t0
        except BaseException:
            for p in plans:
                if p.writers is not None:
                    p.writers.close()
            raise
        finally:
            pool.kill()
        runner = {"kind": "ray", "cluster": where, "nodes": nodes, "actors": n,
                  "actor_resources": "1 GPU, 1 CPU" if gpu else "1 CPU",
                  "actor_restarts": sum(len(p) - 1 for p in pool.pids.values()),
                  "frames_resent": pool.resent, "actor_nodes": pool.nodes,
                  "runs": len(plans)}
        runner["frames_wall_s"] = wall  # all runs' frames, from the first sent to the last written
        runner["frames_per_s"] = frames / wall if frames and wall > 0 else None
        # reading, sending, receiving and writing: the driver's share of a frame, the
        # cluster's ceiling at 1 / driver_s_per_frame frames per second
        runner["driver_s_per_frame"] = (wall - pool.waited) / frames if frames else None
        return [finish_run(p, dict(runner)) for p in plans]


class ActorPool:
    """The driver's view of the actors: which have started, the calls queued on each, and
    where each has run (its processes and node)."""

    def __init__(self, ray, actors: list):
        from ray.exceptions import OutOfMemoryError, RayActorError

        self.ray, self.actors = ray, actors
        self.lost = (RayActorError, OutOfMemoryError)  # the actor's process died
        self.starting = {a.info.remote(): i for i, a in enumerate(actors)}
        self.live: set[int] = set()
        self.load: collections.Counter = collections.Counter()
        self.pids = collections.defaultdict(set)
        self.nodes: dict[str, str] = {}
        self.resent = 0
        self.failed: dict[int, str] = {}  # actors that could not start, with the reason
        self.waited = 0.0  # seconds the driver waited on the actors (the rest it was busy)

    def first_started(self, log=print) -> None:
        """Wait until one actor has started; none could: one line (the first one's reason)."""
        while not self.live:
            if not self.starting:
                i, cause = next(iter(self.failed.items()))
                raise WorkerError(f"--ray: actor {i} could not start: {cause}")
            done, _ = self.ray.wait(list(self.starting), num_returns=1)
            self._started(done[0], log)

    def _started(self, ref, log=print) -> None:
        i = self.starting.pop(ref)
        try:
            info = self.ray.get(ref)
        except self.lost as e:  # the others go on without it (every actor gone: the run stops)
            self.failed[i] = _cause(e)
            if self.live:
                log(f"ray: actor {i} could not start ({self.failed[i]}); going on with the others")
            return
        if not self.live:  # the ones that failed before: now that the run goes on, say so
            for j, cause in self.failed.items():
                log(f"ray: actor {j} could not start ({cause}); going on with the others")
        self.nodes[f"actor {i}"] = info["node"]
        self.pids[i].add(info["pid"])
        self.live.add(i)

    def kill(self) -> None:
        for a in self.actors:
            self.ray.kill(a, no_restart=True)

    def outcomes(self, refs: list, jobs: list, log=print):
        """Yield (run, frame name, output, error) for every frame of `jobs` ((run, chunk of
        FrameItems), sent in order), keeping IN_FLIGHT calls on every actor that has started.
        `refs[run]`: what FrameActor.process takes for that run.

        The frames of a call whose actor died for good are suspects: each is sent again alone,
        to an actor with nothing in flight, so that it is the first the actor infers and a
        second loss is that frame's own (an actor infers its calls in order: what is sent after
        it cannot take it down). One that kills every actor it reaches is skipped, the frames
        that were queued behind it on its first actor are kept."""
        ray = self.ray
        queue, suspects = collections.deque((r, c, 0) for r, c in jobs), collections.deque()
        in_flight = {}

        def send(i, run, chunk, losses):
            sent = [dataclasses.replace(item, data=_read(item.path) if item.paths is None else  # a rig: each camera's
                                        tuple(None if p is None else _read(p) for p in item.paths)) for item in chunk]
            in_flight[self.actors[i].process.remote(run, refs[run], sent)] = (i, run, chunk, losses)
            self.load[i] += 1

        while queue or suspects or in_flight:
            for i in sorted(self.live, key=lambda i: self.load[i]):
                if suspects and not self.load[i]:
                    send(i, *suspects.popleft())
                # while suspects wait, the actors are let run dry so that one soon takes them
                while queue and self.load[i] < (1 if suspects else IN_FLIGHT):
                    send(i, *queue.popleft())
            if not self.live and not self.starting:
                raise WorkerError("--ray: every actor has died; finished frames are kept, "
                                  "continue with --resume")
            t = time.perf_counter()
            done, _ = ray.wait(list(in_flight) + list(self.starting), num_returns=1)
            self.waited += time.perf_counter() - t
            if done[0] in self.starting:
                self._started(done[0], log)
                continue
            i, run, chunk, losses = in_flight.pop(done[0])
            self.load[i] -= 1
            try:
                info, outcomes = ray.get(done[0])
            except self.lost as e:  # the actor is gone for good: its frames go elsewhere
                if i in self.live:
                    log(f"ray: actor {i} died ({_cause(e)}); its frames go to the other actors")
                self.live.discard(i)
                for item in chunk:
                    if losses + 1 >= MAX_LOSSES:
                        yield run, os.path.basename(item.path), None, (
                            f"{item.path}: the actor inferring it died {MAX_LOSSES} times "
                            f"(killed, or out of memory)")
                    else:
                        self.resent += 1
                        suspects.append((run, [item], losses + 1))
                continue
            if info["pid"] not in self.pids[i]:  # Ray restarted it and retried its calls
                self.pids[i].add(info["pid"])
                self.nodes[f"actor {i}"] = info["node"]
                log(f"ray: actor {i} was restarted (process {info['pid']} on {info['node']}); "
                    f"its unfinished frames were retried there")
            for name, output, error in outcomes:
                yield run, name, output, error


def _read(path: str) -> bytes | None:
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError:
        return None  # the actor reports the file as missing, naming it


def _cause(error) -> str:
    """The line of a Ray error that says why (its last, but Ray's "never ran" remark)."""
    lines = [line.strip() for line in str(error).strip().splitlines() if line.strip()]
    never = [line for line in lines if line.startswith("The actor never ran")]
    lines = [line for line in lines if line not in never]
    return (lines[-1] if lines else type(error).__name__) + (" (it never started)" if never else "")
