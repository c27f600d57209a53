"""The `model` section: the DPOM pixel models and mean-field inference (../shared/MODEL.md), its
defaults those of model.ModelParams."""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from ..model import BEHIND_COST, EXACT_BETA, TOP_SHORTER, ModelParams
from ..values import Bool, Heights, Int, Node, Num, Pair, _d, _fail


class ModelSection(Node):
    """The DPOM pixel models and mean-field inference (../shared/MODEL.md)."""

    prior: Num = Field(_d(ModelParams, "prior"), gt=0, lt=1, description="prior occupancy of every cell")
    sigma_object: Num = Field(_d(ModelParams, "sigma_object"), gt=0,
                              description="spread of an object's surface about the depth its model expects "
                                          "(the solid's surface, or the facing plane), metres")
    sensor_noise: Pair = Field(_d(ModelParams, "sensor_noise"),
                               description="sensor sigma(z) = a + b z^2, metres; adds to sigma_object "
                                           "and floors the background spread")
    outlier_prob: Num = Field(_d(ModelParams, "outlier_prob"), gt=0, lt=1, description="pi_out")
    missing_prob: Num = Field(_d(ModelParams, "missing_prob"), ge=0, lt=1,
                              description="pi_inf of objects and of the floor-only background")
    z_max: Num = Field(_d(ModelParams, "z_max"), gt=0, description="sensor range, metres")
    alpha: Num = Field(_d(ModelParams, "alpha"), description="soft threshold rho* = sigmoid(alpha e + beta) rho")
    beta: Num | None = Field(None, description=f"see alpha; null: {_d(ModelParams, 'beta'):g}, on the exact path "
                                               f"(engine.exact) {EXACT_BETA:g}")
    share_of: Literal["silhouette", "unhidden"] = Field(
        _d(ModelParams, "share_of"), description="eq. 13's e: share of the silhouette, or of its "
        "pixels not hidden by something nearer (README, How it works)")
    damping: Num = Field(_d(ModelParams, "damping"), gt=0, le=1,
                         description="lambda of the damped update at the first iteration")
    damping_growth: Num = Field(_d(ModelParams, "damping_growth"), ge=1, description="growth of lambda per iteration")
    damping_max: Num | None = Field(None, gt=0, le=1,
                                    description=f"cap of lambda (default {_d(ModelParams, 'damping_max')}, "
                                                f"never below damping)")
    damping_streak: Num = Field(_d(ModelParams, "damping_streak"), ge=1,
                                description="per-location growth of lambda while a location's target stays on one side of "
                                            "its rho (1: off)")
    damping_streak_max: Num = Field(_d(ModelParams, "damping_streak_max"), gt=0, le=1,
                                    description="cap of the per-location lambda (never below the iteration's lambda)")
    tolerance: Num = Field(_d(ModelParams, "tolerance"), gt=0,
                           description="stop when max |rho_new - rho| is below it")
    max_iterations: Int = Field(_d(ModelParams, "max_iterations"), ge=1,
                                description="iteration cap; frames that reach it unconverged are counted")
    check_every: Int = Field(_d(ModelParams, "check_every"), ge=1,
                             description="iterations between convergence checks")
    missing_clip: Num = Field(_d(ModelParams, "missing_clip"), gt=0, lt=0.5,
                              description="background pi_inf is clipped to [c, 1 - c]")
    background_outside_grid: Bool = Field(_d(ModelParams, "background_outside_grid"),
                                          description="floor-only background: readings out of every "
                                                      "object box are background")
    background_occludes: Bool = Field(_d(ModelParams, "background_occludes"),
                                      description="a location does not claim pixels where the known "
                                                  "background is in front of it by occlusion_margin")
    occlusion_margin: Num = Field(_d(ModelParams, "occlusion_margin"), ge=0, description="metres")
    sparse_epsilon: Num = Field(_d(ModelParams, "sparse_epsilon"), ge=0, le=0.5,
                                description="sparse iterations: cells whose rho and rho_new are below "
                                            "it leave the lists until a full pass; 0: every pass full")
    sparse_drop: Num = Field(_d(ModelParams, "sparse_drop"), ge=0, le=1,
                             description="sparse iterations: a full pass also drops, setting its rho to 0, a cell "
                                         "whose rho_new is below sparse_epsilon and rho below this; 0: off")
    bound_rounds: Int = Field(_d(ModelParams, "bound_rounds"), ge=0,
                              description="with sparse iterations: rounds of the pruning bound, which "
                                          "removes before the first pass the cells whose rho_new can "
                                          "never reach sparse_epsilon; 0: no pruning")
    warm_start: Bool = Field(_d(ModelParams, "warm_start"),
                             description="start each frame from the previous frame's rho capped at the "
                                         "prior (not with --workers or --ray)")
    top_support: Num = Field(_d(ModelParams, "top_support"), ge=0, le=1,
                             description="the top-band test: rho* x sigmoid(top_slope (u - top_support)); 0: off")
    top_band: Num = Field(_d(ModelParams, "top_band"), ge=0, lt=1,
                          description="the band starts at top_band x the object height")
    top_hidden: Num = Field(_d(ModelParams, "top_hidden"), ge=0, le=1,
                            description="a hidden band pixel counts as this much of a supporting one")
    top_slope: Num = Field(_d(ModelParams, "top_slope"), gt=0, description="steepness of the top-band sigmoid")
    top_min_pixels: Int = Field(_d(ModelParams, "top_min_pixels"), ge=1,
                                description="fewer readings in the band: not judged")
    top_unseen: Num | None = Field(None, ge=0, le=1,
                                   description="the top-band factor where fewer than top_min_pixels (or "
                                               "top_unseen_part of the silhouette) of the band are in the image "
                                               "(its top out of view); 1: not judged; "
                                               "default 1 with a background (frames or auto: people at the "
                                               "image's edges), 0 floor-only (furniture there passes)")
    top_unseen_share: Num = Field(_d(ModelParams, "top_unseen_share"), ge=0, le=1,
                                  description="where the band is out of view, rho* also x sigmoid(top_slope "
                                              "(e - this)), e eq. 13's share; 0: off")
    top_unseen_part: Num = Field(_d(ModelParams, "top_unseen_part"), ge=0, le=1,
                                 description="a band with fewer than this share of the silhouette's pixels in "
                                             "the image also counts as out of view")
    top_sigmas: Num = Field(_d(ModelParams, "top_sigmas"), ge=0,
                            description="a band pixel supports the object within this many sigma of "
                                        "its depth; 0: the mask test")
    top_heights: Heights | None = Field(None, description=f"heights (metres, below object.height) of shorter people "
                                                          f"whose top band is also tried, the best kept (README, How "
                                                          f"it works); default [object.height - {TOP_SHORTER:g}] with "
                                                          f"the solid on ground grids, objects taller than 1 m and a "
                                                          f"background (frames or auto), else [] (floor-only: "
                                                          f"furniture that tall would pass)")
    top_missing: Num = Field(_d(ModelParams, "top_missing"), ge=0, le=1,
                             description="a band pixel with no reading where the object lies within z_max "
                                         "(the sensor would read it there) and the background is mostly "
                                         "read counts as this much of one reading behind it; 0: none")
    exclusion: Num | None = Field(None, ge=0,
                                  description=f"two objects cannot stand within exclusion_radius: a "
                                              f"location's evidence loses exclusion x its neighbours' rho "
                                              f"above exclusion_gate (README, How it works); default "
                                              f"{_d(ModelParams, 'exclusion'):g} on ground grids, 0 (off) "
                                              f"in voxel mode")
    exclusion_radius: Num = Field(_d(ModelParams, "exclusion_radius"), gt=0, description="metres")
    exclusion_gate: Num = Field(_d(ModelParams, "exclusion_gate"), ge=0, lt=1,
                                description="neighbours' rho above it count")
    behind_cost: Num | None = Field(None, ge=0,
                                    description=f"evidence a location loses per pixel of its silhouette's "
                                                f"core that reads behind its object (README, How it works); "
                                                f"default {BEHIND_COST:g} with the solid on "
                                                f"ground grids, else 0 (off: the paper, such pixels say nothing)")
    behind_side: Num = Field(_d(ModelParams, "behind_side"), ge=0, lt=0.5,
                             description="share of each silhouette row left out at either end")
    behind_low: Num = Field(_d(ModelParams, "behind_low"), ge=0, le=1,
                            description="pixels whose object point lies below behind_low x the height "
                                        "are left out (ground grids)")
    behind_high: Num = Field(_d(ModelParams, "behind_high"), ge=0, le=1,
                             description="pixels whose object point lies above behind_high x the height "
                                         "are left out (ground grids)")
    behind_step: int = Field(_d(ModelParams, "behind_step"), ge=1,
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
