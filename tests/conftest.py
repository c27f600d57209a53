import os
import signal

import numpy as np
import pytest
import warp as wp
from hypothesis import settings

# hypothesis: the same examples on every run in CI (a failure there reproduces here with
# CI=true), and the failing example's blob printed everywhere
settings.register_profile("ci", derandomize=True, print_blob=True)
settings.register_profile("dev", print_blob=True)
settings.load_profile("ci" if os.environ.get("CI") else os.environ.get("HYPOTHESIS_PROFILE", "dev"))

# the Ctrl-C tests send SIGINT to this process and to runs it starts: a suite started as a
# background job of a non-interactive shell (`pytest ... &` in a script) inherits SIGINT
# ignored, Python then raises no KeyboardInterrupt, and its children inherit the ignoring
if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    signal.signal(signal.SIGINT, signal.default_int_handler)

# pytest-xdist (pyproject's addopts: two worker processes, a test file each at a time): a
# kernel cache each, as for any processes that run at once (a cache is written by one process)
if os.environ.get("PYTEST_XDIST_WORKER") and os.environ.get("WARP_CACHE_PATH"):
    os.environ["WARP_CACHE_PATH"] = os.path.join(os.environ["WARP_CACHE_PATH"], os.environ["PYTEST_XDIST_WORKER"])

from dpom_warp.warp_setup import init_warp

wp.config.log_level = wp.LOG_ERROR
init_warp()
DEVICES = ["cpu"] + [str(d) for d in wp.get_cuda_devices()]


@pytest.fixture(params=DEVICES)
def device(request):
    """Every test that takes `device` runs on the CPU and on each CUDA device present."""
    return request.param


def assert_same_sums(got, want, device):
    """Two engines' float results that add the same terms: equal on the CPU, where the sums
    run in pixel order; within 1e-12 (relative) on a GPU, whose atomic adds sum in any order,
    so that two runs of one engine can differ in the last bit."""
    if device == "cpu":
        np.testing.assert_array_equal(got, want)
    else:
        np.testing.assert_allclose(got, want, rtol=1e-12, atol=0)


@pytest.fixture
def rng():
    return np.random.default_rng(1234)


def pytest_report_header(config):
    return f"warp devices: {', '.join(DEVICES)}; WARP_CACHE_PATH={os.environ.get('WARP_CACHE_PATH', 'default')}"


TOP_KEYS = ("top_support", "top_against", "top_hidden", "top_missing", "top_seen")  # prior.top_counts' order


def assert_top_counts(engine, want):
    """The engine's top-band counts (people.PeoplePrior.top_counts) equal the reference's
    (mean_field's top_support ... top_seen), exactly: they are integers."""
    for key, counts in zip(TOP_KEYS, engine.prior.top_counts, strict=True):
        np.testing.assert_array_equal(counts.numpy(), want[key], err_msg=key)



# pytest-xdist hands the test files out in the order collected (--no-loadscope-reorder), two to
# each process at the start, then one to whichever is free: the longest go first, so that the
# run does not end waiting on one of them, and the two Ray files one after the other in the
# same process, not at once (measured 2026-12-07 under two processes on the 2-core VM: the Ray
# files 105 to 117 s each, the golden runs 103 s, the long runs 88 s, the API's 75 s, the floor
# fits' 68 s; the rest 60 s or less). The others keep their order, and every file its own.
LONGEST_FIRST = ("test_ray_cluster.py", "test_golden.py", "test_ray.py", "test_long_runs.py", "test_face.py",
                 "test_ground.py")


def pytest_collection_modifyitems(config, items):
    rank = {name: i for i, name in enumerate(LONGEST_FIRST)}
    items.sort(key=lambda item: rank.get(item.path.name, len(LONGEST_FIRST)))
