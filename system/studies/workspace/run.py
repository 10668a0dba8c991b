"""A workspace study run: :func:`run` computes everything its file asks for into a :class:`Workspace`."""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from robofmu.system.studies.workspace.measures import GII, Maps, Radii, joint_grid_gii, maps, radii, region_gii
from robofmu.system.studies.workspace.study import Study, characteristic_length


@dataclass
class Workspace:
    study: Study
    length: float
    centre: tuple[float, float]
    radii: Radii
    maps: Maps
    regions: list[GII]
    joint: list[GII]
    seconds: float


def run(study: Study, joint_grids: list[int] | None = None, progress=lambda text: None) -> Workspace:
    """Everything the study asks for (``joint_grids`` replaces its full joint grids)."""
    from robofmu.components.robots import load_model

    start = time.perf_counter()
    model = load_model(study.robot)
    length = characteristic_length(study, model)
    centre = study.centre
    if centre is None:
        home = model.fk_many(np.asarray(model.configuration("home"), dtype=float))
        centre = (float(home[0]), float(home[1]))
    grids = study.grids
    progress(f"radii: {grids['rays']} rays x {grids['ray_orientations']} orientations, bisection and zoom")
    r = radii(model, centre, grids["rays"], grids["ray_orientations"])
    half = 1.05 * float(r.reachable.max())
    progress(f"maps: {grids['positions']}² positions x {grids['orientations']} orientations")
    m = maps(model, centre, half, grids, study.theta, length)
    progress(f"GII over {len(study.regions)} regions")
    regions = [region_gii(model, centre, region, length, grids["region"]) for region in study.regions]
    joint = []
    for n in joint_grids or grids["joint"]:
        progress(f"GII over the full joint grid {n}³")
        joint.append(joint_grid_gii(model, n, length, centre))
    return Workspace(study, length, centre, r, m, regions, joint, time.perf_counter() - start)
