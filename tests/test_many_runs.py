"""Many simulations in one process, as a parameter sweep does them: each FMU extracted to its own
folder, which fmpy deletes after every run. Run in a fresh interpreter that has not imported
robofmu (as a user's sweep script), so the package comes from the first FMU's extraction folder."""
from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from fmu_util import robot_blocks

#: One parameter per block kind and two values of it: runs alternate between them.
VARIED = {"plant": ("g", 9.81, 3.0), "controller": ("g", 9.81, 3.0), "fk": None, "ik": None,
          "trajectory": None, "jacobian": None}
#: Where gravity does no work (3rrp, a horizontal plane) g changes nothing: vary these instead.
WITHOUT_GRAVITY = {"plant": ("qd0[1]", 0.0, 0.5), "controller": ("q_ref[1]", 0.0, 0.01)}
TRAJECTORY = {"waypoints": ("cruise_factor", 1.5, 1.8), "line": ("a_max", 0.0375, 0.02),
              "joint_bangbang": ("a_max[1]", 3.0, 1.5), "circle": ("cruise_factor", 1.5, 1.8),
              "pose_line": ("cruise_factor", 1.5, 1.8)}

SCRIPT = textwrap.dedent("""
    import json, sys
    import numpy as np
    from fmpy import simulate_fmu
    path, name, a, b, runs = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
    out = []
    for k in range(runs):
        start = {name: a if k % 2 == 0 else b} if name else {}
        r = simulate_fmu(path, stop_time=0.02, step_size=1e-3, output_interval=0.02, start_values=start)
        out.append([float(v) for v in r[-1]])
    assert "robofmu" in sys.modules and "site-packages" not in sys.modules["robofmu.components"].__file__
    print("RESULT " + json.dumps(out))
""")


@pytest.mark.parametrize("robot, kind", robot_blocks())
def test_simulate_fmu_ten_times_in_one_process(fmu_root, robot, kind):
    from robofmu.components.robots import load_description

    from robofmu.components.robots import load_model

    varied = VARIED[kind] if kind != "trajectory" else TRAJECTORY[load_description(robot).trajectory.kind]
    if kind == "ik" or kind == "fk":
        varied = None
    model = load_model(robot)
    if kind in WITHOUT_GRAVITY and not any(model.gravity_torque(model.configuration("home"))):
        varied = WITHOUT_GRAVITY[kind]
    name, a, b = varied if varied else ("", 0.0, 0.0)
    proc = subprocess.run([sys.executable, "-c", SCRIPT, str(fmu_root / robot / f"{kind}.fmu"), name,
                           repr(a), repr(b), "10"], capture_output=True, text=True, timeout=300, cwd="/")
    assert proc.returncode == 0, proc.stderr[-3000:]
    rows = json.loads(next(line for line in proc.stdout.splitlines() if line.startswith("RESULT "))[7:])
    assert len(rows) == 10
    for k, row in enumerate(rows):
        assert row == rows[k % 2], f"run {k + 1} differs from run {k % 2 + 1} with the same parameters"
    assert all(abs(v) < 1e6 for v in rows[0])
    if name:
        assert rows[0] != rows[1], f"{name} = {a} and {b} gave the same outputs"
