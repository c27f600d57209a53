"""The --ray driver's scheduling (cluster.ActorPool.outcomes) against a stand-in for Ray whose
actors infer their calls in order and die at a poisoned frame: every frame comes back once,
only the poisoned frames are skipped, and a frame sent again after a loss is always the first
its actor infers. Deterministic (calls complete in the order they were made), so every case
the real cluster's timing rarely gives is tried."""

import itertools
import os

import pytest
from ray.exceptions import RayActorError

from dpom_warp import cluster
from dpom_warp.worker import FrameItem


class Ref:
    def __init__(self, value=None, error=None):
        self.value, self.error = value, error


class FakeRay:
    """ray.wait / get / kill for Ref objects; calls complete in the order they were made."""

    def __init__(self):
        self.made = []

    def wait(self, refs, num_returns=1):
        first = min(refs, key=self.made.index)
        return [first], [r for r in refs if r is not first]

    def get(self, ref):
        if ref.error is not None:
            raise ref.error
        return ref.value

    def kill(self, actor, no_restart=True):
        actor.dead = True


class Method:
    def __init__(self, fn):
        self.remote = fn


class FakeActor:
    """An actor that infers its calls in order: a call with a poisoned frame ends its process,
    so that call and every later one fail (the earlier ones have finished)."""

    def __init__(self, ray, index, poison, sent):
        self.ray, self.index, self.poison, self.sent, self.dead = ray, index, poison, sent, False
        self.pool = None  # the pool sending to it: its calls in flight when one is made
        self.info = Method(lambda: self._ref(self._info()))
        self.process = Method(self._process)

    def _info(self):
        return {"pid": 1000 + self.index, "node": "fake"}

    def _ref(self, value):
        ref = Ref(error=RayActorError()) if self.dead else Ref(value)
        self.ray.made.append(ref)
        return ref

    def _process(self, run, refs, items):
        self.sent.append((self.index, [os.path.basename(it.path) for it in items], self.pool.load[self.index]))
        if any(os.path.basename(it.path) in self.poison for it in items):
            self.dead = True
        return self._ref((self._info(), [(os.path.basename(it.path), "output", None) for it in items]))


def schedule(frames, poison, actors, chunk=1, broken=(), log=None):
    """Run ActorPool.outcomes over `frames` frames in chunks of `chunk`; returns the outcomes
    by frame name, the calls in the order sent ((actor, names, calls in flight on it before)),
    and the pool."""
    ray, sent = FakeRay(), []
    pool = cluster.ActorPool(ray, [FakeActor(ray, i, poison, sent) for i in range(actors)])
    for actor in pool.actors:
        actor.pool = pool
    for i in broken:  # these could not start: their info call fails
        ref = next(r for r, k in pool.starting.items() if k == i)
        ref.value, ref.error = None, RayActorError()
    log = log if log is not None else (lambda *_: None)
    pool.first_started(log)
    names = [f"{i:04d}.png" for i in range(frames)]
    jobs = [(0, [FrameItem(n) for n in names[k:k + chunk]]) for k in range(0, frames, chunk)]
    got = {}
    for run, name, output, error in pool.outcomes([None], jobs, log=log):
        assert name not in got, f"{name} came back twice"
        got[name] = error or output
    assert sorted(got) == names  # every frame once
    return got, sent, pool


@pytest.mark.parametrize("frames, poisoned, actors, chunk", [
    (12, (1,), 3, 1), (12, (2, 3), 5, 1), (16, (1, 6), 6, 1), (16, (0, 9), 6, 2), (20, (3, 4, 11), 8, 1),
])
def test_only_the_frames_that_kill_actors_are_skipped(frames, poisoned, actors, chunk):
    poison = {f"{i:04d}.png" for i in poisoned}
    got, sent, pool = schedule(frames, poison, actors, chunk)
    skipped = {name for name, what in got.items() if what != "output"}
    assert skipped == poison
    for name in poison:
        assert got[name].endswith(f"the actor inferring it died {cluster.MAX_LOSSES} times (killed, or out of memory)")
    assert actors - len(pool.live) <= cluster.MAX_LOSSES * len(poison)  # at most two actors each
    # after a loss a frame goes alone, as the first call of an actor with nothing in flight
    seen = set()
    for actor, names, in_flight in sent:
        if any(n in seen for n in names):
            assert len(names) == 1 and in_flight == 0, (actor, names, in_flight)
        seen.update(names)
    assert seen == set(got)


def test_a_suspect_is_resent_without_waiting_for_the_rest_of_the_run():
    """The actors are let run dry while a suspect waits: it goes again long before the last
    new frame is sent (not at the end of a long run)."""
    got, sent, _ = schedule(40, {"0000.png"}, 4)
    firsts = [k for k, (_, names, _) in enumerate(sent) if names == ["0000.png"]]
    assert len(firsts) == 2 and firsts[1] < 10 and got["0000.png"] != "output"


def test_many_orders_of_two_poisoned_frames():
    """Every place for two poisoned frames among 10, three actors to spare: never an innocent
    frame skipped."""
    for a, b in itertools.combinations(range(10), 2):
        poison = {f"{a:04d}.png", f"{b:04d}.png"}
        got, _, _ = schedule(10, poison, 2 * cluster.MAX_LOSSES + 3)
        assert {n for n, what in got.items() if what != "output"} == poison, (a, b)


def test_every_actor_dead_is_the_one_line_error():
    with pytest.raises(cluster.WorkerError, match="every actor has died"):
        schedule(6, {"0001.png", "0004.png"}, 3)


def test_actors_that_cannot_start_leave_the_work_to_the_others():
    """Actor 0 (the first to answer) and actor 2 cannot start: the others infer every frame,
    each failure said in a line; none can start: one line naming the first."""
    lines = []
    got, sent, pool = schedule(10, set(), 4, broken=(0, 2), log=lines.append)
    assert set(got.values()) == {"output"} and {a for a, _, _ in sent} == {1, 3}
    assert sorted(pool.failed) == [0, 2] and sum("could not start" in line for line in lines) == 2
    with pytest.raises(cluster.WorkerError, match=r"^--ray: actor 0 could not start: "):
        schedule(4, set(), 2, broken=(0, 1))
