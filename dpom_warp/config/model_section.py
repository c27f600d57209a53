"""The `model` section: the DPOM pixel models and mean-field inference (../shared/MODEL.md). Its
fields, bounds and defaults are model.ModelParams' own; the section adds the defaults that
depend on the rest of the config (null: chosen by `build` from the grid, the object, the
background and the path)."""

from __future__ import annotations

from pydantic import Field

from ..model import BEHIND_COST, EXACT_BETA, TOP_SHORTER, ModelParams
from ..values import Heights, Num

_PARAMS = ModelParams()  # the defaults the automatic ones start from


class ModelSection(ModelParams):
    """The DPOM pixel models and mean-field inference (../shared/MODEL.md)."""

    beta: Num | None = Field(None, description=f"see alpha; null: {_PARAMS.beta:g}, on the exact path "
                                               f"(engine.exact) {EXACT_BETA:g}")
    damping_max: Num | None = Field(None, gt=0, le=1,
                                    description=f"cap of lambda (default {_PARAMS.damping_max}, "
                                                f"never below damping)")
    top_unseen: Num | None = Field(None, ge=0, le=1,
                                   description="the top-band factor where fewer than top_min_pixels (or "
                                               "top_unseen_part of the silhouette) of the band are in the image "
                                               "(its top out of view); 1: not judged; "
                                               "default 1 with a background (frames or auto: people at the "
                                               "image's edges), 0 floor-only (furniture there passes)")
    top_heights: Heights | None = Field(None, description=f"heights (metres, below object.height) of shorter people "
                                                          f"whose top band is also tried, the best kept (README, How "
                                                          f"it works); default [object.height - {TOP_SHORTER:g}] with "
                                                          f"the solid on ground grids, objects taller than 1 m and a "
                                                          f"background (frames or auto), else [] (floor-only: "
                                                          f"furniture that tall would pass)")
    exclusion: Num | None = Field(None, ge=0,
                                  description=f"two objects cannot stand within exclusion_radius: a "
                                              f"location's evidence loses exclusion x its neighbours' rho "
                                              f"above exclusion_gate (README, How it works); default "
                                              f"{_PARAMS.exclusion:g} on ground grids, 0 (off) "
                                              f"in voxel mode")
    behind_cost: Num | None = Field(None, ge=0,
                                    description=f"evidence a location loses per pixel of its silhouette's "
                                                f"core that reads behind its object (README, How it works); "
                                                f"default {BEHIND_COST:g} with the solid on "
                                                f"ground grids, else 0 (off: the paper, such pixels say nothing)")

    def build(self, grid_mode: str, shape: str, height: float, background: bool, exact: bool) -> ModelParams:
        """The model's parameters, each null chosen for this config: `grid_mode` ('ground' or
        'voxel'), the object's `shape` and `height`, whether there is a `background` (frames or
        auto) and the `exact` path (engine.exact: every pass full, no warm start)."""
        ground, solid = grid_mode == "ground", shape == "solid"
        auto = {
            "damping_max": max(_PARAMS.damping_max, self.damping),
            "exclusion": _PARAMS.exclusion if ground else 0.0,
            "behind_cost": BEHIND_COST if ground and solid else 0.0,  # the core is the solid's
            # a person shorter than the solid; not floor-only, where the band is what tells
            # furniture from people and a shorter one lets a cabinet of that height through
            "top_heights": (round(height - TOP_SHORTER, 6),) if ground and solid and height > 1.0 and background else (),
            # a cell whose band is out of the image is not judged by it (people entering the view, a
            # ceiling camera's edges); floor-only it is rejected: a table at the image's edge supports
            # the lower part of such a solid, and without a background nothing tells it from a person
            "top_unseen": 1.0 if background else 0.0,
            # eq. 13's cut-off, chosen for each path on the tuning draw (README, Defaults and why)
            "beta": EXACT_BETA if exact else _PARAMS.beta,
        }
        values = {k: (auto[k] if k in auto and v is None else v) for k, v in self.model_dump().items()}
        if exact:
            values.update(sparse_epsilon=0.0, warm_start=False)
        return ModelParams(**values)
