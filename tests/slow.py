"""Slowing a subprocess's frames down, so that a signal sent after its first frame is written
arrives while it still runs (the signal tests then never depend on the machine's speed).

`slow_env(tmp_path, seconds)` returns an environment whose Python processes (the run, and
Ray's workers, which inherit it) sleep `seconds` before each FrameWorker.process call: a
sitecustomize on PYTHONPATH patches dpom_warp.worker when it is first imported. With
DPOM_TEST_NO_READ=FOLDER in the environment too, those processes cannot open files under
FOLDER (a cluster node without the frames: they must come as bytes); with DPOM_TEST_CRASH=END,
a FrameWorker.process call given a frame whose path ends with END ends its process at once
(os._exit: a frame that takes down its actor); with DPOM_TEST_RESTARTS=N, a driver gives its
Ray actors N restarts (cluster.ACTOR_RESTARTS)."""

import os
from pathlib import Path

HOOK = '''
import importlib.abc, importlib.machinery, os, sys, time

DELAY = {delay!r}
CRASH = os.environ.get("DPOM_TEST_CRASH")


def _slow_frames(module):
    real = module.FrameWorker.process

    def process(self, items, *args, **kwargs):
        if CRASH and any(item.path.endswith(CRASH) for item in items):
            os._exit(3)
        time.sleep(DELAY)
        return real(self, items, *args, **kwargs)

    module.FrameWorker.process = process


def _restarts(module):
    if os.environ.get("DPOM_TEST_RESTARTS"):
        module.ACTOR_RESTARTS = int(os.environ["DPOM_TEST_RESTARTS"])


class _Patches(importlib.abc.MetaPathFinder):
    """Patches a module of dpom_warp when it is first imported."""

    patches = dict([("dpom_warp.worker", _slow_frames), ("dpom_warp.cluster", _restarts)])  # no braces: .format

    def find_spec(self, name, path, target=None):
        patch = self.patches.pop(name, None)
        if patch is None:
            return None
        spec = importlib.machinery.PathFinder.find_spec(name, path)
        run_module = spec.loader.exec_module

        def exec_module(module):
            run_module(module)
            patch(module)

        spec.loader.exec_module = exec_module
        return spec


sys.meta_path.insert(0, _Patches())

import builtins  # noqa: E402

_NO_READ = os.environ.get("DPOM_TEST_NO_READ")
if _NO_READ:  # this process may not open files under that folder (a node without the frames)
    _open = builtins.open

    def _guarded(file, *args, **kwargs):
        if isinstance(file, (str, os.PathLike)) and os.path.abspath(os.fspath(file)).startswith(_NO_READ):
            raise PermissionError(13, "this node has no access to the frames", os.fspath(file))
        return _open(file, *args, **kwargs)

    builtins.open = _guarded
'''


def slow_env(tmp_path: Path, seconds: float) -> dict:
    folder = tmp_path / "slow-frames"
    folder.mkdir(exist_ok=True)
    (folder / "sitecustomize.py").write_text(HOOK.format(delay=seconds))
    env = {**os.environ, "PYTHONUNBUFFERED": "1"}
    env["PYTHONPATH"] = os.pathsep.join([str(folder)] + [p for p in [env.get("PYTHONPATH")] if p])
    return env
