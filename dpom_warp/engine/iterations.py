"""The mean-field iterations: the evidence pass, the exclusion prior, the damped update and
the convergence check, launched from Python or replayed as a captured graph."""

from __future__ import annotations

import ctypes
import math

import numpy as np
import warp as wp

from .. import kernels as K


def _direct(cmd):
    """(entry point, argument block, field names, its address) of a recorded CPU launch that
    Warp invokes with a ctypes block of its arguments (warp's `invoke`, whose block type it
    caches per kernel at the first launch), for Engine._launch to call the entry point with
    a block it keeps; None where the launch is not such (a GPU, tiles, another Warp)."""
    try:
        if not cmd.device.is_cpu or cmd.block_dim > 1 or cmd.adjoint:
            return None
        cached = cmd.kernel._invoke_cache.get((tuple(type(p) for p in cmd.params[1:]), False))
        if cached is None:
            return None
        block_type, fields = cached
        block = block_type()
        names = [f[0] for f in fields]
        for i, name in enumerate(names):
            setattr(block, name, cmd.params[1 + i])
        return cmd.hooks.forward, block, names, ctypes.byref(block)
    except (AttributeError, TypeError, ValueError):
        return None


class _Recorded:
    """Engine._launch's record of one kernel: Warp's recorded command, the dim and inputs of
    its last launch, its direct call (_direct's tuple; None: Warp's Launch.launch) and, for a
    direct call, the bounds of the current dim and those of each dim seen (ctypes refs)."""

    __slots__ = ("cmd", "dim", "inputs", "direct", "bounds", "bounds_of")

    def __init__(self, cmd, dim: int, inputs: list, direct):
        self.cmd, self.dim, self.inputs, self.direct = cmd, dim, list(inputs), direct
        self.bounds = ctypes.byref(cmd.params[0])
        self.bounds_of = {dim: self.bounds}


class IterationsMixin:
    """Engine: the iteration loop."""

    def iterate(self, it: int, logit_prior: float, damping: float, full: bool = True):
        """One mean-field iteration: evidence pass, then damped update (recording
        max |rho_new - rho| as max_change[frame, it]) of the frames not done. A full pass
        walks every list and updates every location; otherwise the compact lists of the live
        locations (see `compact`) and only those move (kernels.sparse)."""
        full_lists = full or self.sparse_on_lists
        lists = self.lists if full_lists else self.compact_lists
        pixels, active = self.batch * self.n_pixels, self.no_index
        if not full_lists and self.n_active is not None:  # the pixels with live entries alone
            pixels, active = self.n_active, self.active
        elif full_lists and self.n_listed is not None:  # the pixels with entries alone
            pixels, active = self.n_listed, self.listed
        launch, p = self._launch, self.params
        if pixels:
            launch(K.evidence_pass, pixels, [lists, self.delta_bg, self.rho, self.behind, self.evidence,
                                             self.n_pixels, self.done, self.local_scratch, active])
        index, dim = self.no_index, self.batch * self.n_locations
        if not full and self.n_live is not None:  # the live locations alone (gather_live)
            index, dim = self.live_index, self.n_live
        elif full and self.n_kept is not None:  # all but the pruned and idle ones
            index, dim = self.kept_index, self.n_kept
        if not dim:
            if len(index):  # nothing to update: the iteration still counts
                launch(K.count_iteration, self.batch, [it, self.done, self.iterations])
            return
        if p.exclusion > 0:  # neighbours above the gate push each other down
            launch(K.exclusion_pass, dim, [p.exclusion, p.exclusion_gate, self.rho, self.neighbour_start,
                                           self.neighbours, self.evidence, self.n_locations, self.done,
                                           int(full), self.live, index])
        launch(K.update_rho, dim, [logit_prior, damping, it, self.evidence, self.rho, self.n_locations,
                                   self.done, self.max_change, self.iterations, int(full), p.sparse_epsilon,
                                   self.live, index, self.live_changed, self.streak, p.damping_streak,
                                   p.damping_streak_max, p.behind_cost, self.n_behind, p.sparse_drop])

    def _launch(self, kernel, dim: int, inputs: list):
        """wp.launch of one of a frame's kernels, recorded at its first launch (one record a
        kernel) and replayed after with only the arguments that changed: a launch from Python
        takes ~15 to 30 us on the CPU, and a frame makes ~200. On the CPU outside a capture a
        replay calls the kernel's entry point with an argument block kept between launches (its
        changed fields rewritten, its bounds kept per dim) instead of Warp's Launch.launch,
        which builds the block anew each time (`_direct`)."""
        rec = self._recorded.get(kernel)
        if rec is None:
            cmd = wp.launch(kernel, dim=dim, inputs=inputs, device=self.device, record_cmd=True)
            cmd.launch()
            self._recorded[kernel] = _Recorded(cmd, dim, inputs, _direct(cmd) if self.direct_launch else None)
            return
        cmd, last, direct = rec.cmd, rec.inputs, rec.direct
        for i, v in enumerate(inputs):
            if v is not last[i] and not (type(v) is type(last[i]) and type(v) in (int, float) and v == last[i]):
                last[i] = v
                if direct is None:
                    cmd.set_param_at_index(i, v)
                elif type(v) in (int, float):  # (the iteration, the damping: the block's field takes it)
                    setattr(direct[1], direct[2][i], v)
                else:
                    cmd.set_param_at_index(i, v)
                    setattr(direct[1], direct[2][i], cmd.params[1 + i])
        if dim != rec.dim:
            rec.dim = dim
            if direct is None:
                cmd.set_dim(dim)
            else:  # the bounds of a dim seen before are reused (a few dims recur each frame)
                bounds = rec.bounds_of.get(dim)
                if bounds is None:
                    if len(rec.bounds_of) > 64:
                        rec.bounds_of.clear()
                    cmd.set_dim(dim)
                    bounds = rec.bounds_of[dim] = ctypes.byref(cmd.params[0])
                rec.bounds = bounds
        if direct is None:
            cmd.launch()
        else:
            direct[0](rec.bounds, direct[3])

    def _check(self, it: int):
        self._launch(K.check_converged, self.batch, [it, self.params.tolerance, self.max_change, self.done])

    def _iterate_all(self, logit_prior: float):
        """The whole loop: up to max_iterations, each frame stopping at its first check
        (every check_every iterations) whose largest change is below the tolerance. With
        sparse iterations the checked iterations are full passes, so a frame stops only when
        a pass over every location has found nothing to revive."""
        p = self.params
        full, self.n_live, self.n_active, self.sparse_on_lists = True, None, None, False
        self.live_changed.zero_()
        for it in range(p.max_iterations):
            was_full, full = full, p.full_pass(it)
            if not full and was_full:
                self._compact_if_changed()
            self.iterate(it, logit_prior, p.damping_at(it), full)
            if (it + 1) % p.check_every == 0:
                self._check(it)
                if not self.graph and self.done.numpy().all():
                    break

    def _run_loop(self, logit_prior: float):
        if not self.graph:
            self._iterate_all(logit_prior)
            return
        lists = (self.lists.loc.ptr, self.capacity)
        if self._graph is None or self._graph_lists != lists:  # new list buffers: new graph
            with wp.ScopedCapture(device=self.device) as capture:
                self._iterate_all(logit_prior)
            self._graph, self._graph_lists = capture.graph, lists
        wp.capture_launch(self._graph)

    def _start(self, n: int, start: np.ndarray | None) -> tuple[float, bool]:
        """Every frame's rho at its start (the prior, `start`, or with warm_start the last frame's
        capped at the prior), the loop's state cleared, padding frames done; then, with sparse
        iterations, the pruning bound. Returns (logit of the prior, whether the bound ran)."""
        p = self.params
        if start is None and p.warm_start and self._last_rho is not None:
            # capped at the prior: locations found empty start (nearly) empty, while occupied
            # ones start afresh (starting them occupied holds moving people back, +3 cm)
            start = np.minimum(self._last_rho, p.prior)
        if start is None:
            self.rho.fill_(p.prior)
        else:
            self.rho.assign(np.tile(np.asarray(start, dtype=np.float64), self.batch))
        self.live.fill_(1)
        self.streak.zero_()
        self.evidence.zero_()
        self.max_change.zero_()
        self.iterations.zero_()
        self.done.assign(np.arange(self.batch, dtype=np.int32) >= n)  # padding frames: done
        logit_prior = math.log(p.prior) - math.log1p(-p.prior)
        bound = p.sparse_epsilon > 0 and p.bound_rounds > 0
        self.n_kept = self.n_listed = None
        if p.sparse_epsilon > 0:  # the bound, then locations in no list stay where they start
            self.prune(logit_prior)
            if not self.graph:  # full passes update all but the pruned and idle ones, and the
                # passes over the lists run over the pixels with entries (read after one sync)
                self.n_kept = self._gather(self.kept_index)
                self.n_listed = int(self.n_listed_out.numpy()[0])
        if p.behind_cost > 0 and not bound:  # (with the bound, prune counted them first)
            self._count_behind()
        return logit_prior, bound
