"""The mean-field iterations: the evidence pass, the exclusion prior, the damped update and
the convergence check, launched from Python or replayed as a captured graph."""

from __future__ import annotations

import math

import numpy as np
import warp as wp

from .. import kernels as K


class IterationsMixin:
    """Engine: the iteration loop."""

    def iterate(self, it: int, logit_prior: float, damping: float, full: bool = True):
        """One mean-field iteration: evidence pass, then damped update (recording
        max |rho_new - rho| as max_change[frame, it]) of the frames not done. A full pass
        walks every list and updates every location; otherwise the compact lists of the live
        locations (engine.sparse) and only those move (kernels.sparse)."""
        full_lists = full or self.sparse_on_lists
        launch, p = self._launch, self.params
        for v in self.views:  # every camera's pixels add to each location's evidence
            lists = v.lists if full_lists else v.compact_lists
            pixels, active = self.batch * v.n_pixels, self.no_index
            if not full_lists and v.n_active is not None:  # the pixels with live entries alone
                pixels, active = v.n_active, v.active
            elif full_lists and v.n_listed is not None:  # the pixels with entries alone
                pixels, active = v.n_listed, v.listed
            if pixels:
                v.launch(K.evidence_pass, pixels, [lists, v.delta_bg, self.rho, v.behind, self.evidence, v.n_pixels,
                                                   self.done, self.local_scratch, active])
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
                                   p.damping_streak_max, self.prior.cost, self.prior.n_behind, p.sparse_drop])

    def _check(self, it: int):
        self._launch(K.check_converged, self.batch, [it, self.params.tolerance, self.max_change, self.done])

    def _iterate_all(self, logit_prior: float):
        """The whole loop: up to max_iterations, each frame stopping at its first check
        (every check_every iterations) whose largest change is below the tolerance. With
        sparse iterations the checked iterations are full passes, so a frame stops only when
        a pass over every location has found nothing to revive."""
        p = self.params
        full, self.n_live, self.sparse_on_lists = True, None, False
        for v in self.views:
            v.n_active = None
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
        lists = tuple((v.lists.loc.ptr, v.capacity) for v in self.views)
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
        self.n_kept = None
        for v in self.views:
            v.n_listed = None
        if p.sparse_epsilon > 0:  # the bound, then locations in no list stay where they start
            self.prune(logit_prior)
            if not self.graph:  # full passes update all but the pruned and idle ones, and the
                # passes over the lists run over the pixels with entries (read after one sync)
                self.n_kept = self._gather(self.kept_index)
                for v in self.views:
                    v.n_listed = int(v.n_listed_out.numpy()[0])
        if not bound:  # the prior's fixed term (with the bound, prune counted it first)
            self.prior.count(self)
        return logit_prior, bound
