"""Sparse iterations: the per-pixel lists compacted to the live locations.

A location with rho = 0 is transparent (MODEL.md): it multiplies T by 1 and adds nothing to B,
so leaving it out of every list leaves the other locations' evidence unchanged. A full pass
(every check_every iterations, and the first and last) updates every location and marks dead
those whose undamped target rho_new is below epsilon, setting rho = rho_new there (damping
only slows the approach to a fixed point, and a location with strongly negative evidence has
nothing to compete for). These kernels then copy each pixel's list, in order, keeping only
the live locations: `count_live` counts, an exclusive scan gives the offsets, `fill_live`
copies. The passes in between run the ordinary evidence pass on the compact lists and update
only live locations. Frames that are done get empty compact lists.
"""

import warp as wp

from .mean_field import frame_of


@wp.kernel(enable_backward=False)
def count_live(
    offsets: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    entry_loc: wp.array(dtype=wp.int32),
    live: wp.array(dtype=wp.int32),
    pixels: int,
    done: wp.array(dtype=wp.int32),
    live_counts: wp.array(dtype=wp.int32),
):
    p = wp.tid()
    n = int(0)
    if done[frame_of(p, pixels)] == 0:
        start = offsets[p]
        for j in range(start, start + counts[p]):
            n += live[entry_loc[j]]
    live_counts[p] = n


@wp.kernel(enable_backward=False)
def fill_live(
    offsets: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    entry_loc: wp.array(dtype=wp.int32),
    entry_delta: wp.array(dtype=wp.float32),
    live: wp.array(dtype=wp.int32),
    live_offsets: wp.array(dtype=wp.int32),
    live_counts: wp.array(dtype=wp.int32),
    live_loc: wp.array(dtype=wp.int32),
    live_delta: wp.array(dtype=wp.float32),
):
    p = wp.tid()
    if live_counts[p] == 0:
        return
    e = live_offsets[p]
    start = offsets[p]
    for j in range(start, start + counts[p]):
        k = entry_loc[j]
        if live[k] != 0:
            live_loc[e] = k
            live_delta[e] = entry_delta[j]
            e += 1
