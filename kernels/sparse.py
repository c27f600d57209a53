"""Sparse iterations: the per-pixel lists compacted to the live locations.

A location with rho = 0 is transparent (MODEL.md): it multiplies T by 1 and adds nothing to B,
so leaving it out of every list leaves the other locations' evidence unchanged. A full pass
(every check_every iterations, and the first and last) updates every location and marks dead
those whose rho and undamped target rho_new are both below epsilon (kernels.mean_field
update_rho; a dead location's rho still moves at every full pass, and it comes back to life
when either rises above epsilon). These kernels then copy each pixel's list, in order, keeping only
the live locations: `count_live` counts, an exclusive scan gives the offsets, `fill_live`
copies (driven from the host, `compact_once` does all three and lists the pixels with live
entries, over which alone the sparse evidence passes run; `compact_again` shrinks the compact
lists in place when only deaths happened since). The passes in between run the ordinary
evidence pass on the compact lists and update only live locations. Frames that are done get empty compact lists.

The pruning bound, before the first pass (`bound_pass`, `update_bound`, `prune`,
`prune_lists`): a few rounds bound every location's rho_new from above over every state the
iterations can reach; a location whose bound is below epsilon can never matter and leaves
every list for the whole frame (rho = 0, transparent), so every pass walks less from the start.
A location left in no list is idle (`mark_idle`): it keeps its start. Driven from the host,
the updates run over an index of the locations that can move (`gather_live`; update_rho's first
thread then counts the iteration, `count_iteration` when no location moves).
"""

from typing import Any

import warp as wp

from .mean_field import (LOCAL_ENTRIES, LOCAL_MEDIUM, LOCAL_SHORT, SIZED_STACK, LocalScratch, LocalScratch16,
                         LocalScratch48, frame_of, sigmoid)
from .pixel_model import PixelLists, f64

PRUNED = -1  # live[k] of a location the pruning bound removed for the whole frame
IDLE = -2  # live[k] of a location in no list: its evidence is 0, it keeps its start


@wp.kernel(enable_backward=False)
def mark_idle(per_location: wp.array(dtype=wp.int32), live: wp.array(dtype=wp.int32)):
    """A location in no list (and not pruned) is IDLE for the frame: rho_new is the prior
    whatever the others do, so it is left where it starts (the prior, or a warm start)."""
    i = wp.tid()
    if per_location[i] == 0 and live[i] != PRUNED:
        live[i] = IDLE


@wp.kernel(enable_backward=False)
def gather_live(
    live: wp.array(dtype=wp.int32),
    locations: int,
    done: wp.array(dtype=wp.int32),
    index: wp.array(dtype=wp.int32),
    count: wp.array(dtype=wp.int32),
):
    """The live locations of the frames not done, into index[0 : count[0]] (the updates of a
    sparse pass launch over these alone; the order does not matter, each is its own)."""
    i = wp.tid()
    if live[i] == 1 and done[frame_of(i, locations)] == 0:
        index[wp.atomic_add(count, 0, 1)] = i


@wp.kernel(enable_backward=False)
def count_iteration(iteration: int, done: wp.array(dtype=wp.int32), iterations: wp.array(dtype=wp.int32)):
    """iterations[frame] = iteration + 1 for the frames not done, in an iteration where no
    location moves (update_rho counts it otherwise)."""
    f = wp.tid()
    if done[f] == 0:
        iterations[f] = iteration + 1


@wp.func
def settled(upper: wp.float64, start: wp.float64, epsilon: wp.float64) -> bool:
    """A location is settled in the pruning bound's rounds when its bound is below epsilon
    and at or below its start rho (so rmax is its start whatever later rounds give): its
    bound stays, and a pixel holding settled locations alone is skipped (bound_pass)."""
    return upper < epsilon and upper <= start


@wp.func
def local_bound(start: int, n: int, b: wp.float64, entry_loc: wp.array(dtype=wp.int32),
                entry_delta: wp.array(dtype=wp.float32), rho: wp.array(dtype=wp.float64),
                upper: wp.array(dtype=wp.float64), evidence: wp.array(dtype=wp.float64), excess: Any,
                clear: Any):
    """bound_pass on one pixel's list of n <= len(excess) entries, with D_j - Bmin_j in
    `excess` and 1 - rmax_j in `clear` (fresh stack vectors of one tier, as
    mean_field.local_evidence)."""
    for jj in range(n):
        j = n - 1 - jj
        rmax = wp.max(rho[entry_loc[start + j]], upper[entry_loc[start + j]])
        x = f64(entry_delta[start + j]) - b
        excess[j] = x
        clear[j] = f64(1.0) - rmax
        if x < f64(0.0):
            b = b + rmax * x
    t = f64(1.0)
    for j in range(n):
        x = excess[j]
        if x >= f64(0.0):
            wp.atomic_add(evidence, entry_loc[start + j], x)
        else:
            wp.atomic_add(evidence, entry_loc[start + j], t * x)
        t = t * clear[j]


@wp.kernel(enable_backward=False)
def bound_pass(
    lists: PixelLists,
    delta_bg: wp.array(dtype=wp.float64),
    rho: wp.array(dtype=wp.float64),
    upper: wp.array(dtype=wp.float64),
    behind: wp.array(dtype=wp.float64),
    evidence: wp.array(dtype=wp.float64),
    pixels: int,
    done: wp.array(dtype=wp.int32),
    local: int,
    settle: wp.float64,
):
    """One round of the pruning bound (reference.evidence_bound): with rmax = max(rho, upper)
    (rho: the start; no iteration takes a location above it), a back-to-front pass gives
    Bmin_j, the least B_j can be, and a front-to-back pass Tmin_j, the least T_j can be; pixel
    i adds to k_j's `evidence` x = D_j - Bmin_j where x >= 0, else Tmin_j x: at least what it
    adds in any iteration. One thread per pixel of the batch, skipping frames that are done.
    With `local` (CPU) the scratch of lists up to LOCAL_ENTRIES is on the stack, as in
    mean_field.evidence_pass; otherwise in the global `behind`. A location is settled when its
    bound is below `settle` (epsilon) and at or below its start (so rmax is its start whatever
    later rounds give): update_bound keeps its bound, and a pixel whose every location is
    settled adds nothing anyone uses, so it is skipped (half the demo frame's entries in the
    second and third rounds)."""
    p = wp.tid()
    n = lists.counts[p]
    if n == 0:
        return
    if done[frame_of(p, pixels)] != 0:
        return
    start = lists.offsets[p]
    skip = int(1)  # every location of the pixel settled
    for j in range(start, start + n):
        k = lists.loc[j]
        if not settled(upper[k], rho[k], settle):
            skip = 0
            break
    if skip == 1:
        return
    b = delta_bg[p]
    if local != 0 and n <= LOCAL_ENTRIES:
        if local == SIZED_STACK and n <= LOCAL_SHORT:
            local_bound(start, n, b, lists.loc, lists.delta, rho, upper, evidence, LocalScratch16(), LocalScratch16())
        elif local == SIZED_STACK and n <= LOCAL_MEDIUM:
            local_bound(start, n, b, lists.loc, lists.delta, rho, upper, evidence, LocalScratch48(), LocalScratch48())
        else:
            local_bound(start, n, b, lists.loc, lists.delta, rho, upper, evidence, LocalScratch(), LocalScratch())
        return
    for jj in range(n):
        j = start + n - 1 - jj
        behind[j] = b
        k = lists.loc[j]
        x = f64(lists.delta[j]) - b
        if x < f64(0.0):
            b = b + wp.max(rho[k], upper[k]) * x
    t = f64(1.0)
    for j in range(start, start + n):
        k = lists.loc[j]
        x = f64(lists.delta[j]) - behind[j]
        if x >= f64(0.0):
            wp.atomic_add(evidence, k, x)
        else:
            wp.atomic_add(evidence, k, t * x)
        t = t * (f64(1.0) - wp.max(rho[k], upper[k]))


@wp.kernel(enable_backward=False)
def update_bound(
    logit_prior: wp.float64,
    behind_cost: wp.float64,
    behind: wp.array(dtype=wp.int32),
    evidence: wp.array(dtype=wp.float64),
    upper: wp.array(dtype=wp.float64),
    settle: wp.float64,
    rho: wp.array(dtype=wp.float64),
):
    """upper <- min(upper, sigmoid(logit(prior) + the round's bound - behind_cost x behind)),
    behind[i] the location's readings behind its object (people.behind_count), a fixed
    part of its evidence (update_rho subtracts it the same way), except for a settled location
    (bound_pass: upper < settle and upper <= rho, its start), whose bound stays as it is;
    clears the evidence."""
    i = wp.tid()
    u = upper[i]
    if not settled(u, rho[i], settle):
        upper[i] = wp.min(u, sigmoid(logit_prior + evidence[i] - behind_cost * f64(behind[i])))
    evidence[i] = f64(0.0)


@wp.kernel(enable_backward=False)
def prune(
    epsilon: wp.float64,
    upper: wp.array(dtype=wp.float64),
    rho: wp.array(dtype=wp.float64),
    live: wp.array(dtype=wp.int32),
):
    """A location whose bound is below epsilon: live = PRUNED and rho = 0 for the frame."""
    i = wp.tid()
    if upper[i] < epsilon:
        live[i] = PRUNED
        rho[i] = f64(0.0)


@wp.kernel(enable_backward=False)
def prune_lists(
    lists: PixelLists,
    live: wp.array(dtype=wp.int32),
    per_location: wp.array(dtype=wp.int32),
    listed: wp.array(dtype=wp.int32),
    n_listed: wp.array(dtype=wp.int32),
):
    """Each pixel's list, in place and in order, without the pruned locations (its count
    shrinks; its offset stays); per_location[k] += the entries of k it keeps (for mark_idle).
    The pixels whose list keeps an entry go to listed[0 : n_listed[0]] (in pixel order on one
    CPU thread): the passes over the lists run over those alone (an empty pixel's thread costs
    ~2 ns, and most of a frame's pixels are empty after the pruning)."""
    p = wp.tid()
    start = lists.offsets[p]
    e = start
    for j in range(start, start + lists.counts[p]):
        k = lists.loc[j]
        if live[k] != PRUNED:
            lists.loc[e] = k
            lists.mu[e] = lists.mu[j]
            lists.delta[e] = lists.delta[j]
            wp.atomic_add(per_location, k, 1)
            e += 1
    lists.counts[p] = e - start
    if e > start:
        listed[wp.atomic_add(n_listed, 0, 1)] = p


@wp.kernel(enable_backward=False)
def count_entries(
    lists: PixelLists,
    per_location: wp.array(dtype=wp.int32),
):
    """per_location[k] += the entries of location k in the lists (prune_lists' count, without
    its copies)."""
    p = wp.tid()
    start = lists.offsets[p]
    for j in range(start, start + lists.counts[p]):
        wp.atomic_add(per_location, lists.loc[j], 1)


@wp.func
def live_entries(lists: PixelLists, live: wp.array(dtype=wp.int32), pixels: int, done: wp.array(dtype=wp.int32),
                 p: int) -> int:
    """Pixel p's entries of live locations (none when its frame is done; the lists hold no
    pruned location, so live is 0 or 1 there)."""
    n = int(0)
    if done[frame_of(p, pixels)] == 0:
        start = lists.offsets[p]
        for j in range(start, start + lists.counts[p]):
            n += live[lists.loc[j]]
    return n


@wp.func
def copy_live(start: int, n: int, entry_loc: wp.array(dtype=wp.int32), entry_delta: wp.array(dtype=wp.float32),
              live: wp.array(dtype=wp.int32), e: int, live_loc: wp.array(dtype=wp.int32),
              live_delta: wp.array(dtype=wp.float32)) -> int:
    """The live entries of the list [start, start + n), in order, to the compact list from e
    (in place when the arrays are the same and e <= start); returns where they end."""
    for j in range(start, start + n):
        k = entry_loc[j]
        if live[k] != 0:
            live_loc[e] = k
            live_delta[e] = entry_delta[j]
            e += 1
    return e


@wp.kernel(enable_backward=False)
def compact_once(
    lists: PixelLists,
    live: wp.array(dtype=wp.int32),
    pixels: int,
    done: wp.array(dtype=wp.int32),
    compact: PixelLists,
    active: wp.array(dtype=wp.int32),
    totals: wp.array(dtype=wp.int32),
):
    """count_live, the scan and fill_live in one pass (the loop driven from the host, no
    graph): each pixel with live entries takes its slice at totals[1] and its place in
    `active` at totals[2] with atomic adds, in pixel order on one CPU thread (in any order on
    a GPU: each slice is still the pixel's own); the sparse evidence passes then run over the
    active pixels alone, on the CPU in the same order as over every pixel (the same sums)."""
    p = wp.tid()
    n = live_entries(lists, live, pixels, done, p)
    compact.counts[p] = n
    if n > 0:
        e = wp.atomic_add(totals, 1, n)
        compact.offsets[p] = e
        active[wp.atomic_add(totals, 2, 1)] = p
        copy_live(lists.offsets[p], lists.counts[p], lists.loc, lists.delta, live, e, compact.loc, compact.delta)


@wp.kernel(enable_backward=False)
def compact_again(
    active: wp.array(dtype=wp.int32),
    compact: PixelLists,
    live: wp.array(dtype=wp.int32),
    pixels: int,
    done: wp.array(dtype=wp.int32),
    active_out: wp.array(dtype=wp.int32),
    totals: wp.array(dtype=wp.int32),
):
    """compact_once from the compact lists themselves, when the full pass since they were made
    only killed locations (none revived: every live one is still in them): each active pixel's
    compact list loses its dead entries in place, in order, and the pixels still holding some
    go to active_out at totals[2] (in order on one CPU thread)."""
    p = active[wp.tid()]
    start = compact.offsets[p]
    e = start
    if done[frame_of(p, pixels)] == 0:
        e = copy_live(start, compact.counts[p], compact.loc, compact.delta, live, start, compact.loc, compact.delta)
    compact.counts[p] = e - start
    if e > start:
        active_out[wp.atomic_add(totals, 2, 1)] = p


@wp.kernel(enable_backward=False)
def count_live(
    lists: PixelLists,
    live: wp.array(dtype=wp.int32),
    pixels: int,
    done: wp.array(dtype=wp.int32),
    compact: PixelLists,
):
    p = wp.tid()
    compact.counts[p] = live_entries(lists, live, pixels, done, p)


@wp.kernel(enable_backward=False)
def fill_live(
    lists: PixelLists,
    live: wp.array(dtype=wp.int32),
    compact: PixelLists,
):
    p = wp.tid()
    if compact.counts[p] > 0:
        copy_live(lists.offsets[p], lists.counts[p], lists.loc, lists.delta, live, compact.offsets[p], compact.loc,
                  compact.delta)


@wp.kernel(enable_backward=False)
def has_entries(live_counts: wp.array(dtype=wp.int32), flag: wp.array(dtype=wp.int32)):
    """flag[p] = 1 where pixel p's compact list holds an entry (the scan's input of
    place_active)."""
    p = wp.tid()
    flag[p] = wp.where(live_counts[p] > 0, 1, 0)


@wp.kernel(enable_backward=False)
def place_active(live_counts: wp.array(dtype=wp.int32), rank: wp.array(dtype=wp.int32),
                 active: wp.array(dtype=wp.int32), active_counts: wp.array(dtype=wp.int32)):
    """The pixels with entries in pixel order (NumPy's np.flatnonzero(live_counts)) and their
    counts, from rank = the inclusive scan of has_entries: each such pixel p is the
    rank[p]-th. No atomics, so the same order on every device."""
    p = wp.tid()
    n = live_counts[p]
    if n > 0:
        active[rank[p] - 1] = p
        active_counts[rank[p] - 1] = n


TALLY_SUM = wp.constant(-(1 << 30))  # frame_tally's code for a sum (no live[k] code is that)


@wp.kernel(enable_backward=False)
def frame_tally(values: wp.array(dtype=wp.int32), per_frame: int, code: int, out: wp.array2d(dtype=wp.int32),
                slot: int):
    """Each frame's tally of `values` (frame i / per_frame) added to out[slot, frame]: their
    sum with code TALLY_SUM, else how many equal `code`: the counts a frame's result reports,
    without copying the per-pixel or per-location arrays back from a GPU."""
    i = wp.tid()
    v = values[i]
    if code == TALLY_SUM:
        if v != 0:
            wp.atomic_add(out, slot, i / per_frame, v)
    elif v == code:
        wp.atomic_add(out, slot, i / per_frame, 1)
