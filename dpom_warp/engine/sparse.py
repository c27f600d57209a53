"""The sparse iterations' bookkeeping over the engine's cameras: the pruning bound and the live
locations gathered with every camera's lists compacted to them."""

from __future__ import annotations

import warp as wp

from .. import kernels as K


class SparseMixin:
    """Engine: which locations the iterations still move, and the lists that hold them."""

    def prune(self, logit_prior: float):
        """The pruning bound from the current rho (the start): params.bound_rounds rounds (each
        camera's pixels bound every location's evidence, then one update), then every location
        whose bound is below sparse_epsilon leaves the lists for the frame (kernels.sparse; no
        host sync). Without rounds nothing is pruned. Either way a location left in no list is
        marked idle."""
        p = self.params
        if p.bound_rounds > 0:
            self.prior.count(self)  # a fixed part of each location's evidence: the bound's too
            self.upper.fill_(1.0)
            self.evidence.zero_()
            for _ in range(p.bound_rounds):
                for v in self.views:
                    v.launch(K.bound_pass, self.batch * v.n_pixels,
                             [v.lists, v.delta_bg, self.rho, self.upper, v.behind, self.evidence, v.n_pixels,
                              self.done, self.local_scratch, p.sparse_epsilon])
                self._launch(K.update_bound, len(self.upper),
                             [logit_prior, self.prior.cost, self.prior.n_behind, self.evidence, self.upper,
                              p.sparse_epsilon, self.rho])
            self._launch(K.prune, len(self.upper), [p.sparse_epsilon, self.upper, self.rho, self.live])
        self.per_location.zero_()
        for v in self.views:
            v.n_listed_out.zero_()
            v.launch(K.prune_lists, self.batch * v.n_pixels,
                     [v.lists, self.live, self.per_location, v.listed, v.n_listed_out])
        self._launch(K.mark_idle, len(self.live), [self.per_location, self.live])

    def _gather(self, index, compact: str | None = None) -> int:
        """The live locations of the frames not done into `index` (kernels.sparse.gather_live);
        returns how many (a host sync). With `compact`, each camera's compact lists first:
        "lists" from the lists in one pass (kernels.sparse.compact_once), "again" from the
        compact lists themselves (compact_again: only deaths since); each camera's n_active,
        its pixels with live entries, is read back with the count."""
        self.live_count.zero_()
        for v in self.views:
            if compact:
                v.live_count.zero_()
            if compact == "lists":
                v.launch(K.compact_once, self.batch * v.n_pixels,
                         [v.lists, self.live, v.n_pixels, self.done, v.compact_lists, v.active, v.live_count])
            elif compact == "again" and v.n_active:
                v.launch(K.compact_again, v.n_active, [v.active, v.compact_lists, self.live, v.n_pixels, self.done,
                                                       v.active_next, v.live_count])
                v.active, v.active_next = v.active_next, v.active
        self._launch(K.gather_live, len(self.live), [self.live, self.n_locations, self.done, index,
                                                     self.live_count])
        count = int(self.live_count.numpy()[0])
        if compact:
            for v in self.views:
                v.n_active = int(v.live_count.numpy()[2])
        return count

    def _compact_if_changed(self):
        """Before a sparse pass: the compact lists. Driven from the host (no graph), they are
        rebuilt only when the full pass changed which locations are live (update_rho's
        `live_changed`), and the sparse updates then run over the live locations alone (their
        count read back with the flag: one sync, where the loop syncs for its check anyway)."""
        if self.graph:
            for v in self.views:
                v.compact(self.live, self.done)
            return
        changed, revived = (int(x) for x in self.live_changed.numpy())
        if self.n_live is not None and not changed:
            return  # the same live locations: the compact lists and the index still hold
        self.live_changed.zero_()
        if self.n_live is None and not changed and self.n_kept is not None:
            # the first full pass killed nothing: the compact lists would be the lists, copied
            self.sparse_on_lists = True
            wp.copy(self.live_index, self.kept_index, count=self.n_kept)
            self.n_live = self.n_kept
            return
        again = self.n_live is not None and not revived and not self.sparse_on_lists
        self.sparse_on_lists = False
        self.n_live = self._gather(self.live_index, compact="again" if again else "lists")
