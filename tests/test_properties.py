"""Property-based: random small scenes and parameters never give NaN, rho outside [0, 1],
or a Warp / NumPy mismatch."""


import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from conftest import DEVICES
from dpom_warp import reference as ref
from dpom_warp.engine import Engine

from scenes import random_scene

params_strategy = st.fixed_dictionaries({
    "prior": st.floats(1e-4, 0.5),
    "sigma_object": st.floats(0.005, 1.0),
    "outlier_prob": st.floats(1e-4, 0.9),
    "missing_prob": st.floats(0.0, 0.9),
    "damping": st.floats(0.01, 1.0),
    "damping_growth": st.floats(1.0, 1.2),
    "damping_streak": st.floats(1.0, 1.5),
    "damping_streak_max": st.floats(0.05, 1.0),
    "max_iterations": st.integers(1, 40),
    "check_every": st.integers(1, 7),
    "alpha": st.floats(-200, 200),
    "beta": st.floats(-20, 20),
    "background_outside_grid": st.booleans(),
})


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1), width=st.integers(8, 48), height=st.integers(6, 40),
       use_frames=st.booleans(), changes=params_strategy)
def test_random_scene_is_finite_bounded_and_matches_reference(seed, width, height, use_frames, changes):
    geom, params, depth, frames = random_scene(seed, width, height)
    changes["damping_max"] = max(changes["damping"], 0.5)
    params = params.replace(**changes)
    bg = ref.background_from_frames(frames, params) if use_frames else ref.floor_background(geom, params, depth)
    want = ref.mean_field(depth, geom, bg, params)
    for device in DEVICES:
        engine = Engine(geom, params, device)
        if use_frames:
            engine.set_background_frames(frames)
        got = engine.infer(depth)
        for a in (got.rho, got.rho_star, got.evidence_share):
            assert np.all(np.isfinite(a))
        assert np.all((got.rho >= 0) & (got.rho <= 1))
        assert np.all((got.rho_star >= 0) & (got.rho_star <= 1))
        assert got.entries == want["entries"] and got.iterations == want["iterations"]
        np.testing.assert_allclose(got.rho, want["rho"], rtol=0, atol=1e-6)
        np.testing.assert_allclose(got.rho_star, want["rho_star"], rtol=0, atol=1e-6)
