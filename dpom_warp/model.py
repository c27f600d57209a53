"""Model parameters and the per-pixel background distribution (MODEL.md, eq. 11)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np
from pydantic import Field, model_validator

from .values import Bool, Heights, Int, Node, Num, Pair, _fail


TOP_MIN_RHO = 1e-3  # locations whose rho* is below it before the top-band test skip it (a factor <= 1)
BEHIND_COST = 2.0  # model.behind_cost's default with the solid on ground grids (config)
EXACT_BETA = -2.5  # model.beta's default on the exact path (engine.exact; config; README, Defaults and why)
TOP_SHORTER = 0.15  # model.top_heights' default: [object.height - TOP_SHORTER] with the solid on ground grids
BAND_ALL = 1e30  # a height band that holds every pixel (the unhidden share of eq. 13)
# a band pixel without a reading counts as missing (ModelParams.top_missing) only where the
# background's pi_inf is below this: a sensor's dead region (never read) says nothing
MISSING_READ = 0.5


class ModelParams(Node):  # the config's `model` section (config.model_section: its automatic defaults)
    """Parameters of the DPOM pixel models and of mean-field inference.

    Attributes:
        prior: prior occupancy probability epsilon of every location.
        sigma_object: spread of an object's surface about the depth its model expects (the
            solid's surface, or the facing plane), metres.
        sensor_noise: (a, b) of the sensor's depth noise sigma(z) = a + b z^2, metres.
        outlier_prob: pi_out, weight of the uniform outlier term.
        missing_prob: pi_inf of objects (and of the floor-only background).
        z_max: sensor range, metres; readings beyond it are treated as no reading.
        alpha, beta: soft threshold rho* = sigmoid(alpha e + beta) rho (eq. 13, corrected sign;
            beta = -3.5 cuts at e = 0.035: MODEL.md's -8, at 0.08, -6.5 and -4.5 cut more
            hidden people in the crowds of the tuning draw, for fewer false detections than
            they save, once the top-band test judged the head, README; the exact path's
            default is EXACT_BETA, config).
        share_of: what e of eq. 13 is a share of: 'silhouette' (MODEL.md: sum of T over the
            mask / |S_k|) or 'unhidden' (/ the silhouette's pixels that read at or behind the
            object: those whose reading is nearer, hidden by something in front, and those
            with no reading are left out). A person hidden but for the head keeps the share
            of its head; an estimate its pixels do not support, or explained away by what is
            in front (small T), is still cut. Measured (README): better without background
            frames in crowds, but phantoms in a crowd with few background frames; off.
        damping: lambda of the damped parallel update rho <- (1 - lambda) rho + lambda rho_new,
            at the first iteration.
        damping_growth: lambda is multiplied by this after every iteration (annealing: small
            steps while neighbours compete, larger ones once the map has settled) ...
        damping_max: ... up to this value (None: no growth beyond `damping`).
        damping_streak: per-location damping: a location whose target rho_new has stayed on
            the same side of its rho for its last s updates takes lambda_k = max(lambda,
            min(damping_streak_max, lambda x damping_streak^s)); a target on the other side
            starts a new run. Neighbours that explain each other away keep changing side
            and keep the annealed lambda; a location heading steadily to 0 (most of the
            grid) or to 1 gets there in a few iterations and leaves the sparse lists early.
            1 (the default): off. Measured (README, How it works): 1.05 with cap 0.6 gives
            31 % fewer iterations on the tuning draw of bench.robustness at about the same
            errors, but the held-out table's median drops 0.975 -> 0.960, so it stays off.
        damping_streak_max: the cap of lambda_k.
        tolerance: stop when max |rho_new - rho| falls below it.
        max_iterations: iteration cap.
        check_every: read the convergence test back to the host every this many iterations.
        missing_clip: background pi_inf is clipped to [missing_clip, 1 - missing_clip].
        background_outside_grid: without background frames, a reading whose 3D point lies
            outside every object box (beyond the grid, or above the objects) is background at
            that depth, instead of broad; walls and ceiling then stop looking like objects.
        background_occludes: a location does not claim a pixel where the (known) background
            is clearly in front of it, mu_bg + occlusion_margin < mu_k (MODEL.md, eq. 4 orders
            the background too): objects behind furniture are hidden, not contradicted.
        occlusion_margin: metres.
        sparse_epsilon: sparse iterations (kernels.sparse): at every full pass (the first, every
            check_every-th and the last iteration) a location whose rho and undamped target
            rho_new are both below this leaves the lists until a later full pass finds them
            above it again; the passes in between run on the live locations only, which alone
            move. 0: every pass is full (the exact path). Damping is the same on both paths:
            dropping a location at once, rho = rho_new, changes which competing neighbour
            wins (measured: robustness MODA down to 0.825), so it is not done by default.
        sparse_drop: with sparse iterations, a full pass also drops a location whose rho_new
            is below sparse_epsilon and whose damped rho is below sparse_drop (but not below
            sparse_epsilon): its rho is set to 0 and it leaves the lists as a dead one, instead
            of decaying from the prior for ~30 iterations while every pass walks it. 0: off
            (the default: on the tuning draw 0.02 saves ~18 % of the time a frame for one
            false detection more, README).
            With sparse iterations, before the first pass, the pruning bound
            (reference.evidence_bound, `bound_rounds` rounds) removes from every list, for
            the whole frame, each location whose rho_new can never reach epsilon from any
            state the iterations can reach (rho = 0 there).
        bound_rounds: rounds of the pruning bound (each a pass over the lists, tightening the
            last); 0: no pruning by the bound.
        warm_start: start a frame from the previous frame's rho instead of the prior.
        top_support: the top-band test of the soft threshold, for objects standing on the
            floor (kernels.people.top_band). In the band of the box from top_band x its
            height to its top, the silhouette pixels with a reading either support the
            object (s: within top_sigmas sigma of its depth), read behind the object (its
            solid, or its facing plane; a: the object would hide them) or in front of it (f:
            hidden by something nearer, which may hide a head: each counts as top_hidden of a
            supporting pixel; 0.25, chosen on the tuning
            draw for people hidden in crowds, README). rho* is multiplied by
            sigmoid(top_slope (u - top_support)), u = (s + top_hidden f) / (s + a + f); a
            band with fewer than top_min_pixels readings, a location whose rho* before the
            test is below TOP_MIN_RHO (rho with share_of unhidden) and voxel grids are not
            judged. A table or cabinet lower than the box shows the
            wall through the band (u = 0); a person's head and shoulders support it (with the
            solid, on the tuning draw of bench.robustness: found people 0.14 to 1, median
            0.6; an arm beside a person seen from above 0.08 to 0.1), also when their legs
            are hidden. 0.05 suits the facing plane. 0: off.
        top_band, top_hidden, top_slope, top_min_pixels: see top_support.
        top_unseen: the top-band factor of a location with fewer than top_min_pixels (or
            top_unseen_part x |S_k|) of its band's pixels in the image, with a reading or not
            (its top out of view: nothing then tells it from furniture as tall as the part in
            view; a table at the edge of a ceiling camera's image supports the lower part of a
            solid whose head lies outside it); 0: not a detection, 1: not judged. 0 here; the config's default is 1
            with a background (frames or auto), where a table is background and such cells
            were mostly people entering or leaving the view (README, Known behaviour).
        top_unseen_share: where the band is out of view (as for top_unseen), rho* is also
            multiplied by sigmoid(top_slope (e - top_unseen_share)), e eq. 13's share: with no
            head to judge, the object must explain this share of its silhouette (a second cell
            beside a person at the image's edge explains a sliver of it). 0: off.
        top_unseen_part: a band also counts as out of view (for top_unseen and
            top_unseen_share) with fewer than this share of the silhouette's pixels |S_k| in the
            image: a sliver of a band at the image's edge reads whatever lies beside the head
            (a person walking out of view, whole in the image but for the top of the head,
            kept 12 band pixels, all reading what lies behind). 0: only top_min_pixels.
        top_sigmas: a band pixel supports the object when its reading is within this many
            sigma of the object's depth (0: when it passes the mask test, ~3.5 sigma with the
            defaults, which let a surface behind a cell's head support it).
        top_heights: heights of people shorter than the object (metres, below its height)
            whose top band is also tried: for each, the band from top_band x that height to
            it on the solid scaled to it (Geometry.shorter), counted as above; a location keeps
            the counts whose factor is the largest. A person of 1.56 m hidden to the head
            fills a quarter of the 1.8 m solid's band (the rest reads the room behind: u ~ 0.1,
            cut), while the band of a 1.65 m solid holds the head (measured with the 1.8 m
            solid; the people config's 1.85 m tries 1.70 m). Where the object's own band
            is out of view (top_unseen_part, top_min_pixels) top_unseen decides, as
            without. () here; the config's default is one, object.height - TOP_SHORTER, with
            the solid on ground grids and a background (frames or auto), chosen on the tuning
            draw (README, How it works); floor-only it is off: there the band is what tells
            furniture from people, and a cabinet as tall as the shorter solid passes it.
        top_missing: a band pixel with no reading where the object lies within z_max (were it
            there, the sensor would read it) counts as this much of one reading behind it: u =
            (s + top_hidden f) / (s + a + f + top_missing m), and a band with no reading at all
            is judged (u = 0). A table far from a ceiling camera at pitch 45: the band above it
            looks at the room beyond the sensor's range and reads nothing; a reading behind the
            object is counted against it, and no reading there says the same, as strongly (the
            model's pi_inf of an object is missing_prob, 0.05). Only where the background is
            mostly read (its pi_inf under MISSING_READ): a sensor's dead region (an Azure
            Kinect's corners, a RealSense's left band), never read in the background frames,
            says nothing; the floor-only background knows no such region and counts every
            pixel. 1 here and in the config (README, Known behaviour); 0: missing readings
            count for none.
        exclusion: two objects cannot stand within exclusion_radius of each other: each
            location's evidence loses exclusion x sum over the locations within the radius
            of max(0, rho - exclusion_gate) / (1 - exclusion_gate) (kernels.mean_field
            exclusion_pass), the mean-field term of a pairwise prior exp(-exclusion x_k x_l)
            counted above the gate; 10 with 0.45 m (people 0.4 m across) cut the misses of the
            tuning draw's close neighbours on the fast path (README); 0: off (the paper's
            independent prior).
        exclusion_radius, exclusion_gate: see exclusion.
        behind_cost: evidence a location loses for each pixel of its silhouette's core whose
            reading lies behind its object beyond the mask test (kernels.people
            behind_count): were the object there, it would hide that reading. MODEL.md's
            masks leave such pixels out, so a cell whose solid half covers a person and half
            the room behind was as good as the person's own; the count does not depend on
            the other locations (a nearer object can only make a reading nearer), so it is
            counted once a frame. The core leaves out, in each image row of the silhouette,
            behind_side of the row's run at each end (arms, a body narrower than the solid)
            and the object points below behind_low x the height (the gap between the legs) or
            above behind_high x the height (heads: people shorter than the solid read behind
            its top; 0.85 x 1.85 m = 1.57 m is about the top of the shortest rendered
            person). Counted on the pixels whose row and column are multiples of behind_step,
            each standing for behind_step^2 pixels (a quarter of the work with 2). Only the
            locations in some list count (the others stay where they start, as before). 0
            here (off: the paper); the config's default is BEHIND_COST with the solid on
            ground grids (its core is the solid's), chosen with behind_high 0.85 on the tuning
            draw (README, How it works).
        behind_side, behind_low, behind_high, behind_step: see behind_cost.
    """

    prior: Num = Field(0.01, gt=0, lt=1, description="prior occupancy of every cell")
    sigma_object: Num = Field(0.1, gt=0,
                              description="spread of an object's surface about the depth its model expects "
                                          "(the solid's surface, or the facing plane), metres")
    sensor_noise: Pair = Field((0.002, 0.0015),
                               description="sensor sigma(z) = a + b z^2, metres; adds to sigma_object "
                                           "and floors the background spread (a Kinect v2's; a floor "
                                           "fit measures the sensor's: summary.json ground_fit.depth_noise, "
                                           "a warning when 1.3x off)")
    outlier_prob: Num = Field(0.05, gt=0, lt=1, description="pi_out")
    missing_prob: Num = Field(0.05, ge=0, lt=1,
                              description="pi_inf of objects and of the floor-only background")
    z_max: Num = Field(10.0, gt=0, description="sensor range, metres")
    alpha: Num = Field(100.0, description="soft threshold rho* = sigmoid(alpha e + beta) rho")
    beta: Num = Field(-3.5, description="see alpha")
    share_of: Literal["silhouette", "unhidden"] = Field(
        "silhouette", description="eq. 13's e: share of the silhouette, or of its "
        "pixels not hidden by something nearer (README, How it works)")
    damping: Num = Field(0.1, gt=0, le=1,
                         description="lambda of the damped update at the first iteration")
    damping_growth: Num = Field(1.03, ge=1, description="growth of lambda per iteration")
    damping_max: Num | None = Field(0.4, gt=0, le=1, description="cap of lambda (None: no growth beyond damping)")
    damping_streak: Num = Field(1.0, ge=1,
                                description="per-location growth of lambda while a location's target stays on one side of "
                                            "its rho (1: off)")
    damping_streak_max: Num = Field(0.6, gt=0, le=1,
                                    description="cap of the per-location lambda (never below the iteration's lambda)")
    tolerance: Num = Field(1e-4, gt=0,
                           description="stop when max |rho_new - rho| is below it")
    max_iterations: Int = Field(100, ge=1,
                                description="iteration cap; frames that reach it unconverged are counted")
    check_every: Int = Field(5, ge=1,
                             description="iterations between convergence checks")
    missing_clip: Num = Field(0.01, gt=0, lt=0.5,
                              description="background pi_inf is clipped to [c, 1 - c]")
    background_outside_grid: Bool = Field(True,
                                          description="floor-only background: readings out of every "
                                                      "object box are background")
    background_occludes: Bool = Field(False,
                                      description="a location does not claim pixels where the known "
                                                  "background is in front of it by occlusion_margin")
    occlusion_margin: Num = Field(0.1, ge=0, description="metres")
    sparse_epsilon: Num = Field(1e-4, ge=0, le=0.5,
                                description="sparse iterations: cells whose rho and rho_new are below "
                                            "it leave the lists until a full pass; 0: every pass full")
    sparse_drop: Num = Field(0.0, ge=0, le=1,
                             description="sparse iterations: a full pass also drops, setting its rho to 0, a cell "
                                         "whose rho_new is below sparse_epsilon and rho below this; 0: off")
    bound_rounds: Int = Field(3, ge=0,
                              description="with sparse iterations: rounds of the pruning bound, which "
                                          "removes before the first pass the cells whose rho_new can "
                                          "never reach sparse_epsilon; 0: no pruning")
    warm_start: Bool = Field(False,
                             description="start each frame from the previous frame's rho capped at the "
                                         "prior (not with --workers or --ray)")
    top_support: Num = Field(0.13, ge=0, le=1,
                             description="the top-band test: rho* x sigmoid(top_slope (u - top_support)); 0: off")
    top_band: Num = Field(0.75, ge=0, lt=1,
                          description="the band starts at top_band x the object height")
    top_hidden: Num = Field(0.25, ge=0, le=1,
                            description="a hidden band pixel counts as this much of a supporting one")
    top_slope: Num = Field(100.0, gt=0, description="steepness of the top-band sigmoid")
    top_min_pixels: Int = Field(3, ge=1,
                                description="fewer readings in the band: not judged")
    top_unseen: Num = Field(0.0, ge=0, le=1, description="the top-band factor where the band is out of view "
                                                          "(top_min_pixels, top_unseen_part); 1: not judged")
    top_unseen_share: Num = Field(0.1, ge=0, le=1,
                                  description="where the band is out of view, rho* also x sigmoid(top_slope "
                                              "(e - this)), e eq. 13's share; 0: off")
    top_unseen_part: Num = Field(0.05, ge=0, le=1,
                                 description="a band with fewer than this share of the silhouette's pixels in "
                                             "the image also counts as out of view")
    top_sigmas: Num = Field(2.0, ge=0,
                            description="a band pixel supports the object within this many sigma of "
                                        "its depth; 0: the mask test")
    top_heights: Heights = Field((), description="heights (metres, below the object's) of shorter people whose "
                                                "top band is also tried, the best kept")
    top_missing: Num = Field(1.0, ge=0, le=1,
                             description="a band pixel with no reading where the object lies within z_max "
                                         "(the sensor would read it there) and the background is mostly "
                                         "read counts as this much of one reading behind it; 0: none")
    exclusion: Num = Field(10.0, ge=0, description="two objects cannot stand within exclusion_radius: a "
                                                   "location's evidence loses exclusion x its neighbours' rho "
                                                   "above exclusion_gate; 0: off")
    exclusion_radius: Num = Field(0.45, gt=0, description="metres")
    exclusion_gate: Num = Field(0.5, ge=0, lt=1,
                                description="neighbours' rho above it count")
    behind_cost: Num = Field(0.0, ge=0, description="evidence a location loses per pixel of its silhouette's "
                                                   "core that reads behind its object; 0: off (the paper)")
    behind_side: Num = Field(0.2, ge=0, lt=0.5,
                             description="share of each silhouette row left out at either end")
    behind_low: Num = Field(0.45, ge=0, le=1,
                            description="pixels whose object point lies below behind_low x the height "
                                        "are left out (ground grids)")
    behind_high: Num = Field(0.85, ge=0, le=1,
                             description="pixels whose object point lies above behind_high x the height "
                                         "are left out (ground grids)")
    behind_step: int = Field(2, ge=1,
                             description="counted on every behind_step-th row and column, each pixel "
                                         "standing for behind_step^2")

    @model_validator(mode="after")
    def _checks(self):
        if min(self.sensor_noise) < 0:
            raise _fail(f"expected [a, b] >= 0, found {list(self.sensor_noise)}", "sensor_noise")
        if self.damping_max is not None and self.damping_max < self.damping:
            raise _fail(f"expected at least model.damping ({self.damping}), found {self.damping_max}",
                        "damping_max")
        return self

    def replace(self, **changes) -> ModelParams:
        """These parameters with `changes`, validated."""
        return type(self)(**{**self.model_dump(), **changes})

    def full_pass(self, iteration: int) -> bool:
        """Whether iteration `iteration` (0-based) is a full pass: always on the exact path;
        with sparse iterations the first, the last, and those ending a check_every block
        (where convergence is checked)."""
        return (self.sparse_epsilon <= 0 or iteration == 0 or iteration == self.max_iterations - 1
                or (iteration + 1) % self.check_every == 0)

    def damping_at(self, iteration: int) -> float:
        """lambda of iteration `iteration` (0-based)."""
        cap = self.damping if self.damping_max is None else self.damping_max
        return min(cap, self.damping * self.damping_growth ** iteration)

    def sensor_sigma(self, z):
        a, b = self.sensor_noise
        return a + b * np.asarray(z, dtype=np.float64) ** 2


# How `input.background: auto` estimates each pixel's background from the run's own frames
# (kernels.background_auto; reference.background_clusters). Each pixel keeps `slots` clusters of
# its readings, streamed frame by frame: a reading joins the nearest cluster when within
# `cluster_sigmas` sensor sigmas plus `cluster_floor` metres of its mean, else starts a new one in
# a free slot or in place of the smallest other than the farthest (of equal ones the nearest):
# people pass in front of the surface that is the background, which must not be pushed out by
# them when it shows rarely. The background is the farthest cluster holding at least `min_share`
# of the frames (people are always in front of the static surface); with no such cluster, a pixel
# whose readings are missing in at least `min_share` of the frames has a broad background, and
# any other pixel (or every pixel, with fewer than `min_frames` frames) falls back to the
# floor-only model. The config's `input.background_auto` section: each field declared here, once.
class AutoBackground(Node):
    """How `input.background: auto` estimates the background from the run's own frames."""

    max_frames: Int = Field(100, ge=1, description="frames used, evenly spread over the sequence")
    min_frames: Int = Field(8, ge=1, description="fewer frames: the floor-only model everywhere")
    min_share: Num = Field(0.2, gt=0, le=1, description="share of the frames a cluster must hold to be the background")
    slots: Int = Field(4, ge=1, le=16, description="clusters kept per pixel")
    cluster_sigmas: Num = Field(3.0, ge=0, description="a reading joins a cluster within cluster_sigmas sensor "
                                                       "sigmas + cluster_floor of its mean")
    cluster_floor: Num = Field(0.03, ge=0, description="metres")

    @model_validator(mode="after")
    def _frames(self):
        if self.min_frames > self.max_frames:
            raise _fail(f"expected at most max_frames ({self.max_frames}), found {self.min_frames}",
                        "min_frames")
        return self

    def state_bytes(self, n_pixels: int) -> int:
        """Device memory of the estimate: per pixel and slot a count (int32) and a running
        mean and sum of squares (float64), plus a per-pixel reading count."""
        return n_pixels * (self.slots * (4 + 8 + 8) + 4)


@dataclass
class Background:
    """Per-pixel background distribution theta_bg,i (arrays of shape (H, W), float64).

    Attributes:
        mu: mean depth, metres.
        sigma: spread, metres.
        missing: pi_inf, probability of no reading.
        outlier: pi_out; 1 means a broad (uniform) distribution over the sensor range.
    """

    mu: np.ndarray
    sigma: np.ndarray
    missing: np.ndarray
    outlier: np.ndarray
