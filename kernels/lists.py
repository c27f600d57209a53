"""Depth order of each pixel's list (near to far, location id breaking ties).

Lists are short (tens of entries), so an in-kernel insertion sort beats a segmented sort.
"""

import warp as wp


@wp.func
def entry_before(mu_a: wp.float32, k_a: wp.int32, mu_b: wp.float32, k_b: wp.int32) -> bool:
    return mu_a < mu_b or (mu_a == mu_b and k_a < k_b)


@wp.kernel(enable_backward=False)
def sort_pixel_lists(
    offsets: wp.array(dtype=wp.int32),
    counts: wp.array(dtype=wp.int32),
    entry_loc: wp.array(dtype=wp.int32),
    entry_mu: wp.array(dtype=wp.float32),
    entry_delta: wp.array(dtype=wp.float32),
):
    p = wp.tid()
    start = offsets[p]
    end = start + counts[p]
    for i in range(start + 1, end):
        k = entry_loc[i]
        mu = entry_mu[i]
        d = entry_delta[i]
        j = i - 1
        while j >= start and entry_before(mu, k, entry_mu[j], entry_loc[j]):
            entry_loc[j + 1] = entry_loc[j]
            entry_mu[j + 1] = entry_mu[j]
            entry_delta[j + 1] = entry_delta[j]
            j -= 1
        entry_loc[j + 1] = k
        entry_mu[j + 1] = mu
        entry_delta[j + 1] = d
