"""Mean-field update of MODEL.md in exclusive form and the damped rho update (eq. 13's soft
threshold, with the people tests, is people.py's).

For pixel i with depth-sorted list k_1..k_n, r_j = rho_{k_j}, D_j = Delta_{k_j,i}:
T_j = prod_{m<j} (1 - r_m);  B_n = Delta_bg,i,  B_j = r_{j+1} D_{j+1} + (1 - r_{j+1}) B_{j+1};
pixel i adds T_j (D_j - B_j) to the evidence of k_j (float64 accumulators).

Frames of a batch are blocks of P pixels and L locations. Each frame stops on its own:
`check_converged` marks a frame done when its largest change of the iteration is below the
tolerance, and the evidence pass and the update then leave it alone, so a batch (and a loop
captured once as a graph, with no host sync) gives every frame what it would get alone.
"""

from typing import Any

import warp as wp

from .pixel_model import PixelLists, f64


@wp.func
def sigmoid(x: wp.float64) -> wp.float64:
    if x >= f64(0.0):
        return f64(1.0) / (f64(1.0) + wp.exp(-x))
    e = wp.exp(x)
    return e / (f64(1.0) + e)


LOCAL_ENTRIES = 128  # lists up to this long keep their scratch in registers / stack
# a stack vector is zeroed where it is declared: tiers keep a short list's zeroing short
# (a 128-entry pair is 2 KiB a pixel, most lists hold 5 to 30 entries)
LOCAL_SHORT, LOCAL_MEDIUM = 16, 48
ONE_STACK, SIZED_STACK = 1, 2  # `local` of the passes: one stack size (LOCAL_ENTRIES), or three
LocalScratch16 = wp.types.vector(length=LOCAL_SHORT, dtype=wp.float64)
LocalScratch48 = wp.types.vector(length=LOCAL_MEDIUM, dtype=wp.float64)
LocalScratch = wp.types.vector(length=LOCAL_ENTRIES, dtype=wp.float64)


@wp.func
def local_evidence(start: int, n: int, b: wp.float64, entry_loc: wp.array(dtype=wp.int32),
                   entry_delta: wp.array(dtype=wp.float32), rho: wp.array(dtype=wp.float64),
                   evidence: wp.array(dtype=wp.float64), excess: Any, clear: Any):
    """evidence_pass on one pixel's list of n <= len(excess) entries, with D_j - B_j in
    `excess` and 1 - r_j in `clear` (fresh stack vectors of one tier)."""
    for jj in range(n):  # back to front: B_j
        j = n - 1 - jj
        r = rho[entry_loc[start + j]]
        d = f64(entry_delta[start + j])
        excess[j] = d - b
        clear[j] = f64(1.0) - r
        b = r * d + clear[j] * b
    t = f64(1.0)
    for j in range(n):  # front to back: T_j and the evidence T_j (D_j - B_j)
        wp.atomic_add(evidence, entry_loc[start + j], t * excess[j])
        t = t * clear[j]


@wp.func
def frame_of(index: int, per_frame: int) -> int:
    """index / per_frame for the few frames of a batch, without an integer division per
    thread (a division per pixel costs ~15 % of a sparse scene's iteration on the CPU)."""
    f = int(0)
    while index >= (f + 1) * per_frame:
        f += 1
    return f


@wp.kernel(enable_backward=False)
def evidence_pass(
    lists: PixelLists,
    delta_bg: wp.array(dtype=wp.float64),
    rho: wp.array(dtype=wp.float64),
    behind: wp.array(dtype=wp.float64),
    evidence: wp.array(dtype=wp.float64),
    pixels: int,
    done: wp.array(dtype=wp.int32),
    local: int,
    active: wp.array(dtype=wp.int32),
):
    """One thread per pixel of the batch, frame after frame, skipping frames that are done;
    with a non-empty `active`, one per pixel it lists (kernels.sparse.compact_once).
    With `local` (CPU), lists of up to LOCAL_ENTRIES keep D_j - B_j and 1 - r_j on the stack,
    in cache, instead of the global scratch `behind` (~15 % faster on one CPU thread); longer
    lists, and every list on a GPU (where a big stack spills), use `behind`. The stack vectors
    are zeroed where declared: SIZED_STACK takes the smallest of 16, 48 and LOCAL_ENTRIES that
    holds the list (ONE_STACK: always LOCAL_ENTRIES, 2 KiB zeroed a pixel; python -m bench
    compares them)."""
    p = wp.tid()
    if active.shape[0] > 0:
        p = active[p]
    n = lists.counts[p]
    if n == 0:
        return
    if done[frame_of(p, pixels)] != 0:  # (Warp evaluates both sides of an `or`)
        return
    start = lists.offsets[p]
    b = delta_bg[p]  # B_n: what lies behind the last entry
    if local != 0 and n <= LOCAL_ENTRIES:
        if local == SIZED_STACK and n <= LOCAL_SHORT:
            local_evidence(start, n, b, lists.loc, lists.delta, rho, evidence, LocalScratch16(), LocalScratch16())
        elif local == SIZED_STACK and n <= LOCAL_MEDIUM:
            local_evidence(start, n, b, lists.loc, lists.delta, rho, evidence, LocalScratch48(), LocalScratch48())
        else:
            local_evidence(start, n, b, lists.loc, lists.delta, rho, evidence, LocalScratch(), LocalScratch())
        return
    for jj in range(n):
        j = start + n - 1 - jj
        behind[j] = b
        r = rho[lists.loc[j]]
        b = r * f64(lists.delta[j]) + (f64(1.0) - r) * b
    t = f64(1.0)
    for j in range(start, start + n):
        k = lists.loc[j]
        wp.atomic_add(evidence, k, t * (f64(lists.delta[j]) - behind[j]))
        t = t * (f64(1.0) - rho[k])


@wp.func
def moves(state: int, full: int) -> bool:
    """Whether update_rho updates a location whose live state is `state` in a pass that is
    `full` or not: never if pruned or idle (< 0), in a sparse pass only if live (1)."""
    return state >= 0 and (full != 0 or state != 0)


@wp.kernel(enable_backward=False)
def update_rho(
    logit_prior: wp.float64,
    damping: wp.float64,
    iteration: int,
    evidence: wp.array(dtype=wp.float64),
    rho: wp.array(dtype=wp.float64),
    locations: int,
    done: wp.array(dtype=wp.int32),
    max_change: wp.array2d(dtype=wp.float64),
    iterations: wp.array(dtype=wp.int32),
    full: int,
    epsilon: wp.float64,
    live: wp.array(dtype=wp.int32),
    index: wp.array(dtype=wp.int32),
    changed: wp.array(dtype=wp.int32),
    streak: wp.array(dtype=wp.int32),
    streak_growth: wp.float64,
    streak_cap: wp.float64,
    behind_cost: wp.float64,
    behind: wp.array(dtype=wp.int32),
    drop: wp.float64,
):
    """rho <- (1 - lambda) rho + lambda sigmoid(logit(prior) + evidence - behind_cost x
    behind), behind[i] the location's silhouette pixels that read behind its object (kernels
    people.behind_count; the evidence they give, which the lists leave out); clears the evidence;
    max_change[frame, iteration] = max |rho_new - rho|; iterations[frame] counts the updates.
    One thread per location of the batch, skipping frames that are done; with a non-empty
    `index`, one thread per location it names (a sparse pass's live ones: kernels.sparse
    gather_live), the first of which counts the iteration of every frame not done.

    Sparse iterations (kernels.sparse): after a full pass (`full` = 1, the evidence of every
    location) a location whose rho and rho_new are both below `epsilon` is marked dead
    (live = 0), any other live, and changed[0] = 1 where that differs from before; after a
    pass over the compact lists (`full` = 0) only live locations move; changed[1] = 1 where a
    dead location comes back to life. With `drop` > 0 a full pass also marks dead, with rho =
    0, a location whose rho_new is below epsilon and whose damped rho is below `drop`
    (ModelParams.sparse_drop). With epsilon = 0 and every pass full this is the exact damped
    update.

    Per-location damping (ModelParams.damping_streak, `streak_growth` > 1): streak[i] is the
    signed count of the location's last updates whose target rho_new lay on the same side of
    rho (+ at or above, - below); an update continuing a run of s takes lambda = max(damping,
    min(streak_cap, damping x streak_growth^s)), one that changes side starts a new run."""
    i = wp.tid()
    indexed = index.shape[0] > 0
    if indexed:
        if i == 0:
            for g in range(done.shape[0]):
                if done[g] == 0:
                    iterations[g] = iteration + 1
        i = index[i]
    f = frame_of(i, locations)
    if done[f] != 0:
        return
    if not indexed and i == f * locations:
        iterations[f] = iteration + 1
    if not moves(live[i], full):  # pruned or idle (kernels.sparse); dead in a sparse pass
        return
    rho_new = sigmoid(logit_prior + evidence[i] - behind_cost * f64(behind[i]))
    wp.atomic_max(max_change, f, iteration, wp.abs(rho_new - rho[i]))
    evidence[i] = f64(0.0)
    lam = damping
    if streak_growth > f64(1.0):  # per-location lambda: the run of targets on one side of rho
        step = int(1)
        if rho_new < rho[i]:
            step = -1
        run = int(0)
        if streak[i] * step > 0:
            run = wp.abs(streak[i])
        lam = wp.max(damping, wp.min(streak_cap, damping * wp.pow(streak_growth, f64(run))))
        streak[i] = step * (run + 1)
    rho[i] = (f64(1.0) - lam) * rho[i] + lam * rho_new
    now = int(1)
    if full != 0 and rho_new < epsilon:
        if rho[i] < epsilon:
            now = 0
        elif rho[i] < drop:
            rho[i] = f64(0.0)
            now = 0
    if now != live[i]:
        changed[0] = 1
        if now == 1:
            changed[1] = 1  # revived (kernels.sparse.compact_again needs none)
    live[i] = now


@wp.kernel(enable_backward=False)
def exclusion_pass(
    strength: wp.float64,
    gate: wp.float64,
    rho: wp.array(dtype=wp.float64),
    neighbour_start: wp.array(dtype=wp.int32),
    neighbours: wp.array(dtype=wp.int32),
    evidence: wp.array(dtype=wp.float64),
    locations: int,
    done: wp.array(dtype=wp.int32),
    full: int,
    live: wp.array(dtype=wp.int32),
    index: wp.array(dtype=wp.int32),
):
    """Two objects cannot stand closer than the exclusion radius: each location l with rho_l
    above the gate subtracts strength x (rho_l - gate) / (1 - gate) from the evidence of its
    neighbours (the locations within the radius) that update_rho will update in this pass
    (`moves`), so each gets strength x the sum over its
    neighbours. Launched between the evidence pass and update_rho: it reads rho before the
    update and writes only the evidence. One thread per location of the batch, or per location
    update_rho's `index` names (every location above the gate moves in the pass: its rho is
    above epsilon); the few above the gate do the work."""
    i = wp.tid()
    if index.shape[0] > 0:
        i = index[i]
    f = frame_of(i, locations)
    r = rho[i]
    if done[f] != 0 or r <= gate:
        return
    push = strength * (r - gate) / (f64(1.0) - gate)
    k = i - f * locations
    for j in range(neighbour_start[k], neighbour_start[k + 1]):
        n = f * locations + neighbours[j]
        if moves(live[n], full):
            wp.atomic_sub(evidence, n, push)


@wp.kernel(enable_backward=False)
def check_converged(
    iteration: int,
    tolerance: wp.float64,
    max_change: wp.array2d(dtype=wp.float64),
    done: wp.array(dtype=wp.int32),
):
    f = wp.tid()
    if done[f] == 0 and max_change[f, iteration] < tolerance:
        done[f] = 1


@wp.kernel(enable_backward=False)
def transparency_pass(
    lists: PixelLists,
    rho: wp.array(dtype=wp.float64),
    visible: wp.array(dtype=wp.float64),
):
    """visible[k] = sum over i in M_k of T_{k,i}: the unhidden, supported part of S_k."""
    p = wp.tid()
    start = lists.offsets[p]
    t = f64(1.0)
    for j in range(start, start + lists.counts[p]):
        k = lists.loc[j]
        wp.atomic_add(visible, k, t)
        t = t * (f64(1.0) - rho[k])
