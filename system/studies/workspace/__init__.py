"""`robofmu workspace`: reachable and dexterous workspace, orientation range and isotropy of a
robot model with vectorized kinematics (a parallel mechanism).

What is computed (all NumPy-vectorized, chunked so that memory stays bounded):

- **Radii** by bisection along rays from a centre: for a bearing beta and an orientation theta,
  rho*(beta, theta) is the largest distance along the ray at which the pose has an IK solution
  (the feasible set along a ray at fixed theta is taken to be an interval from the centre). The
  reachable radius along the ray is max over theta of rho*, the dexterous one min over theta;
  both extremes are first found on a theta grid, then zoomed into (the maximum is a corner of
  rho*, where the leg that limits the reach changes, so a grid alone converges only linearly).
  The workspace radius is the smallest ray radius (the largest disc about the centre inside the
  workspace); the largest is reported too.
- **Maps** on a pose grid (x, y, theta) through ``ik_many``: reachable (some theta), dexterous
  (every theta of the grid), the orientation range (the measure of the feasible thetas), and the
  local isotropy 1/cond(J) at a chosen theta and at the best theta of a grid.
- **GII** = min sigma_min(J) / max sigma_max(J) over named regions (a disc about the centre and
  an orientation window, sampled on a polar grid through the IK) and over full joint grids
  q_j in [-pi, pi) of N points per joint, with the theta row of J multiplied by a characteristic
  length L (so that every row is in m/rad). On a full joint grid the exact singular values are
  computed only where the cheap bounds from the Frobenius norm F and |det J| (sqrt(F^2/3) <=
  sigma_max <= F, 2 |det| / F^2 <= sigma_min <= |det|^(1/3)) leave a configuration in the
  running the extremes; the result is exact.

The robot-specific choices (centre, orientation, grid sizes, regions, L, expected radii, the
report's text) are a study file ``system/studies/*.toml`` with ``kind = "workspace"``.

Modules: :mod:`.study` (the file, read and checked), :mod:`.measures` (the vectorized measures),
:mod:`.run` (a study's run), :mod:`.report` (figures and report); this package exports them all.
"""
from __future__ import annotations

from robofmu.system.studies.workspace.measures import (CHUNK, GII, Maps, Radii, Region, feasible, isotropy, joint_grid_gii, maps,
                                                      orientation_count, radii, ray_reach, region_gii)
from robofmu.system.studies.workspace.report import figures, report_lines, write
from robofmu.system.studies.workspace.run import Workspace, run
from robofmu.system.studies.workspace.study import (MAX_JOINT_GRID, REQUIRED, Study, characteristic_length,
                                                   check_robot, grid_memory, read_study, studies, study_for)

__all__ = ["CHUNK", "GII", "MAX_JOINT_GRID", "Maps", "REQUIRED", "Radii", "Region", "Study", "Workspace",
           "characteristic_length", "check_robot", "feasible", "figures", "grid_memory", "isotropy", "joint_grid_gii",
           "maps", "orientation_count", "radii", "ray_reach", "read_study", "region_gii", "report_lines", "run", "studies",
           "study_for", "write"]
