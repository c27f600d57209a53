"""The joint test's lists: what the test needs of one frame for its candidate locations, as the
engine hands them over with the frame's result, and each candidate's log posterior odds at the
binary state where the other candidates are present (detect.joint_detections prunes with them;
README, How it works). The NumPy reference computes the same odds from the whole per-pixel lists
(reference.joint_log_odds), which the tests compare with."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .geometry import neighbour_lists
from .model import ModelParams


@dataclass
class JointLists:
    """What the joint test needs of one frame, for its candidate locations (those that can be
    detections: rho* at or above the detection threshold), as the engine hands it over with
    the frame's result (Engine.joint_threshold): the per-pixel lists of the pixels whose masks
    hold a candidate, kept to the candidates' entries in the lists' order (near to far) and
    given one pixel after another, with each pixel's Delta_bg; each candidate's behind_cost x
    readings behind its object (behind_count) and its position. `log_odds(cells)` is
    reference.joint_log_odds(frame, geom, bg, params, cells) for cells among the candidates, without
    the frame: other locations' entries are transparent at that binary state (rho 0), so leaving
    them out changes no sum. The lists stay flat (no padding): at a binary state only each
    pixel's first and second present entries count."""

    cells: np.ndarray  # (n,) int64, the candidates' location indices, ascending
    count: np.ndarray  # (P,) int64: each of the P pixels' entries, which follow one another
    L: np.ndarray  # (E,) int64: each entry's position in `cells`
    D: np.ndarray  # (E,) float64: Delta of each entry
    dbg: np.ndarray  # (P,) float64: Delta_bg of each pixel
    behind: np.ndarray  # (n,) float64: behind_cost x readings behind each candidate's object
    locations: np.ndarray  # (n, 3) the candidates' centres (the exclusion prior)
    logit_prior: float
    exclusion: float
    exclusion_radius: float

    @classmethod
    def of_batch(cls, cells, active, count, loc, delta, dbg, behind, locations, params: ModelParams,
                 n_locations: int, n_pixels: int) -> list["JointLists"]:
        """Each frame's JointLists of a batch at once, what of_entries gives frame by frame:
        `cells` (ascending) and `active` (ascending, the pixels with entries) index the batch
        (frame f's from f x n_locations and f x n_pixels); each active pixel's `count` entries
        (`loc`, `delta`) follow one another in list order, and `dbg` is its Delta_bg; `behind`
        (frames, n_locations); `locations` (n_locations, 3). Each frame's fields are slices of
        the batch's arrays."""
        cells, active, count = (np.asarray(a, np.int64) for a in (cells, active, count))
        frames = len(behind)
        cell_at = np.searchsorted(cells, np.arange(frames + 1) * n_locations)
        row_at = np.searchsorted(active, np.arange(frames + 1) * n_pixels)
        entry_at = np.concatenate([[0], np.cumsum(count)])[row_at]
        position = np.zeros(frames * n_locations, np.int64)  # each cell's place among its frame's
        position[cells] = np.arange(len(cells)) - cell_at[cells // n_locations]
        L, D, dbg = position[loc], np.asarray(delta, np.float64), np.asarray(dbg, np.float64)
        logit_prior = float(np.log(params.prior) - np.log1p(-params.prior))
        out = []
        for f in range(frames):
            rows, entries = slice(row_at[f], row_at[f + 1]), slice(entry_at[f], entry_at[f + 1])
            mine = cells[cell_at[f]:cell_at[f + 1]] - f * n_locations
            out.append(cls(mine, count[rows], L[entries], D[entries], dbg[rows],
                           np.asarray(behind[f, mine], np.float64), np.asarray(locations[mine], np.float64),
                           logit_prior, float(params.exclusion), float(params.exclusion_radius)))
        return out

    def log_odds(self, cells) -> np.ndarray:
        """(len(cells),) float64: each cell's log posterior odds with the other `cells` present
        and every other location empty (joint_log_odds); every cell must be a candidate."""
        cells = self.candidates(cells)
        return self.logit_prior + (self.pixel_terms(cells) - self.exclusion_terms(cells))

    def candidates(self, cells) -> np.ndarray:
        """`cells` as int64, a ValueError where one is not among the frame's candidates."""
        cells = np.asarray(cells, np.int64)
        outside = cells[~np.isin(cells, self.cells)]
        if len(outside):
            raise ValueError(f"joint test: cells {sorted(set(outside.tolist()))} are not among the frame's "
                             f"candidates (rho* at or above the detection threshold)")
        return cells

    def pixel_terms(self, cells) -> np.ndarray:
        """(len(cells),) the part of log_odds this camera's pixels give: each cell's evidence at
        the binary state where `cells` are present, less its behind cost (a rig's cameras add)."""
        cells = np.asarray(cells, np.int64)
        at = np.searchsorted(self.cells, cells)
        present = np.zeros(len(self.cells), bool)
        present[at] = True
        return self._evidence(present)[at] - self.behind[at]

    def exclusion_terms(self, cells) -> np.ndarray:
        """(len(cells),) exclusion x each cell's neighbours among `cells` (as mean_field finds them)."""
        cells = np.asarray(cells, np.int64)
        if self.exclusion <= 0:
            return np.zeros(len(cells))
        start, _ = neighbour_lists(self.locations[np.searchsorted(self.cells, cells)], self.exclusion_radius)
        return self.exclusion * np.diff(start)

    def _evidence(self, present) -> np.ndarray:
        """(len(self.cells),) each candidate's evidence_sums at the binary state `present`
        (bool by position in cells), from the flat lists: T_j is 1 up to a pixel's first present
        entry and 0 behind it, and B_j there is the D of the pixel's second present entry, else
        its Delta_bg, so a present cell's sum is over the pixels where it is first (the same
        terms, in the same order, as evidence_sums on the padded lists)."""
        on = present[self.L]
        seen = np.concatenate([[0], np.cumsum(on)])  # present entries before each entry
        rank = seen[1:] - np.repeat(seen[np.cumsum(self.count) - self.count], self.count)  # 1: first
        pixel = np.repeat(np.arange(len(self.count)), self.count)
        B = self.dbg.copy()
        second = on & (rank == 2)
        B[pixel[second]] = self.D[second]
        first = on & (rank == 1)
        return np.bincount(self.L[first], weights=self.D[first] - B[pixel[first]], minlength=len(self.cells))


@dataclass
class RigJointLists:
    """The joint test of a rig's frame: one JointLists a camera, over the same candidates. The
    prior and the exclusion act once per location, every camera's pixels (evidence and behind
    cost) add: log_odds is reference.joint_log_odds_rig."""

    cameras: list[JointLists]

    @property
    def cells(self) -> np.ndarray:
        return self.cameras[0].cells

    def log_odds(self, cells) -> np.ndarray:
        """(len(cells),) each cell's log posterior odds with the other `cells` present (JointLists.log_odds)."""
        first = self.cameras[0]
        cells = first.candidates(cells)
        return first.logit_prior + (sum(c.pixel_terms(cells) for c in self.cameras) - first.exclusion_terms(cells))
