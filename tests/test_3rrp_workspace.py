"""The workspace analysis (system/studies/workspace/) on the planar 3-RRP mechanism: radii, orientation
range, isotropy, GII over regions and over refined full joint grids, and the CLI's mistakes.

Run time is not asserted (the report states it)."""
from __future__ import annotations

import math
import subprocess
import sys

import numpy as np
import pytest

from robofmu.components.robots import load_model
from robofmu.system.studies import workspace

CLI = [sys.executable, "-m", "robofmu.system.cli"]


@pytest.fixture(scope="module")
def model():
    return load_model("3rrp")


@pytest.fixture(scope="module")
def study():
    return workspace.study_for("3rrp")


def test_the_study_names_its_choices(study, model):
    assert study.robot == "3rrp"
    assert workspace.characteristic_length(study, model) == model.r       # L = r, by name
    assert study.centre == (0.0, 0.0) and study.regions


def test_radii_within_a_thousandth(model):
    r = model.r
    radii = workspace.radii(model, (0.0, 0.0), rays=36, orientations=90)
    for values, expected in ((radii.reachable, 2.0 * r / math.sqrt(3.0)), (radii.dexterous, r)):
        assert values.min() == pytest.approx(expected, rel=1e-3)
        assert values.max() == pytest.approx(expected, rel=1e-3)
        assert np.max(np.abs(values / expected - 1.0)) < 1e-6                 # far better than asked


def test_a_grid_alone_is_coarse_but_zoom_refines(model, monkeypatch):
    """Without the zoom, a grid of 90 orientations misses the reachable radius by more than 0.1 %
    (the maximum is a corner of the per-orientation reach); the dexterous one is a smooth minimum."""
    monkeypatch.setattr(workspace.measures, "ZOOM_LEVELS", 0)
    r = model.r
    radii = workspace.radii(model, (0.0, 0.0), rays=36, orientations=90)
    assert radii.reachable.min() < 2.0 * r / math.sqrt(3.0) * (1 - 1e-3)
    assert radii.dexterous.max() == pytest.approx(r, rel=1e-3)


def test_orientation_range_per_position(model):
    """Measure of the feasible theta at distance rho: 2 pi within r, 2 pi - 12 arccos(r / rho)
    between r and 2r/sqrt(3) (each line's distance from O is at most r), 0 beyond."""
    r, k = model.r, 1440
    rho = np.array([0.0, 0.5, 0.99, 1.01, 1.05, 1.1, 1.15, 1.16]) * r
    beta = np.linspace(0.0, 2.0 * math.pi, 5, endpoint=False)[:, None]
    count = workspace.orientation_count(model, rho * np.cos(beta) + 0.0, rho * np.sin(beta), k)
    measure = count * 2.0 * math.pi / k
    expected = np.where(rho <= r, 2.0 * math.pi,
                        np.clip(2.0 * math.pi - 12.0 * np.arccos(np.minimum(r / np.maximum(rho, 1e-300), 1.0)),
                                0.0, None))
    np.testing.assert_allclose(measure, np.broadcast_to(expected, measure.shape), atol=8 * 2 * math.pi / k)


def test_isotropy_of_known_configurations_against_the_scalar_jacobian(model, rng):
    L = model.r
    scale = np.diag([1.0, 1.0, L])
    home = model.configuration("home")
    pose = model.fk(home)
    iso = workspace.isotropy(model, pose[None], L)[0]
    assert iso == pytest.approx(1.0 / np.linalg.cond(scale @ model.jacobian(home)), rel=1e-10)
    assert iso == pytest.approx(1.0 / math.sqrt(2.0), rel=1e-10)             # sigma = sqrt(2/3) r twice, sqrt(1/3) L
    rho = 0.9 * model.r * np.sqrt(rng.uniform(size=20))
    beta = rng.uniform(-math.pi, math.pi, 20)
    poses = np.stack([rho * np.cos(beta), rho * np.sin(beta), rng.uniform(-math.pi, math.pi, 20)], axis=-1)
    values = workspace.isotropy(model, poses, L)
    expected = [1.0 / np.linalg.cond(scale @ model.jacobian(model.ik(p))) for p in poses]
    np.testing.assert_allclose(values, expected, rtol=1e-8)
    assert np.isnan(workspace.isotropy(model, np.array([[0.3, 0.0, 0.0]]), L)[0])   # out of reach


def test_region_gii_is_bounded_away_from_zero_and_converges(model):
    region = workspace.Region("disc 0.5 r", 0.5, (-math.pi, math.pi))
    values = [workspace.region_gii(model, (0.0, 0.0), region, model.r, sizes).gii
              for sizes in ((6, 12, 12), (11, 24, 24), (21, 48, 48), (41, 96, 96))]
    assert min(values) > 0.5
    assert abs(values[-1] - values[-2]) < 1e-3 and abs(values[-2] - values[-3]) < 1e-2
    rim = workspace.region_gii(model, (0.0, 0.0), workspace.Region("disc r", 1.0, (-math.pi, math.pi)),
                               model.r, (11, 24, 24))
    assert rim.gii == pytest.approx(0.0, abs=1e-12)       # the rim of the dexterous disc is singular


def test_full_joint_grid_gii_tends_to_zero(model):
    L = model.r
    grids = [workspace.joint_grid_gii(model, n, L, (0.0, 0.0)) for n in (10, 20, 40, 80)]
    gii = np.array([g.gii for g in grids])
    assert np.all(np.diff(gii) < 0) and gii[-1] < gii[0] / 10
    assert np.all(np.diff([g.sigma_max for g in grids]) > 0)                  # towards direct singularities
    assert gii[-1] < 1e-4 < 0.5 < workspace.region_gii(
        model, (0.0, 0.0), workspace.Region("disc 0.5 r", 0.5, (-math.pi, math.pi)), L, (11, 24, 24)).gii
    for n in (6, 12, 24):         # a multiple of 3 points per joint: the grid holds inverse singularities
        assert workspace.joint_grid_gii(model, n, L, (0.0, 0.0)).gii == 0.0


def test_the_pruned_joint_grid_is_exact(model):
    n, L = 20, model.r
    g = -math.pi + 2.0 * math.pi * np.arange(n) / n
    q = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    sv = model.singular_values_many(q, L)
    ok = np.isfinite(sv).all(-1)
    found = workspace.joint_grid_gii(model, n, L, (0.0, 0.0))
    assert found.sigma_min == sv[ok, 2].min() and found.sigma_max == sv[ok, 0].max()
    assert found.unreachable == int((~ok).sum()) and found.exact < n ** 3 / 2
    x = model.fk_many(q)
    assert found.reach == pytest.approx(np.nanmax(np.hypot(x[:, 0], x[:, 1])), rel=1e-15)


def cli(*args, cwd):
    return subprocess.run([*CLI, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=300)


SMALL = """kind = "workspace"
robot = "3rrp"
characteristic_length = "r"
theta = -60.0
[expected]
reachable = 1.1547005383792515
dexterous = 1.0
[grids]
positions = 21
orientations = 12
isotropy_positions = 11
isotropy_orientations = 6
rays = 12
ray_orientations = 36
joint = [6, 10]
region = [5, 8, 8]
[[regions]]
name = "disc 0.5 r"
radius = 0.5
theta = [-180.0, 180.0]
"""


@pytest.mark.slow
def test_cli_runs_a_study_file(tmp_path):
    (tmp_path / "small.toml").write_text(SMALL)
    done = cli("workspace", "small.toml", "--out", "ws", "--grid", "12", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    names = sorted(p.name for p in (tmp_path / "ws").iterdir())
    assert names == ["gii.png", "isotropy.png", "orientation_range.png", "report.md", "workspace.png"]
    report = (tmp_path / "ws" / "report.md").read_text()
    assert "| reachable | 230.940108 |" in report and "| 12³ = 1728 |" in report and "| 6³ = 216 |" in report
    assert "reachable radius 230.940108 mm, dexterous radius 200.000000 mm" in done.stdout


@pytest.mark.parametrize("args, fragments", [
    (["chess"], ["robot 'chess'", "no vectorized kinematics", "ik_many"]),
    (["no-such-robot"], ["unknown robot 'no-such-robot'; described robots: 3rrp"]),
    (["3rrp", "--grid", "1"], ["--grid 1: must be a whole number", "1000"]),
    (["3rrp", "--grid", "5000"], ["--grid 5000: must be"]),
    (["missing.toml"], ["missing.toml: no such study file"]),
    (["bad.toml"], ["bad.toml: grids.rays: missing key"]),
    (["typo.toml"], ["typo.toml: centr: unknown key (known: ", "did you mean 'centre'?"]),
    (["serial.toml"], ["serial.toml: robot: robot 'rrp'", "no vectorized kinematics"]),
    (["3rrp", "--out", "afile"], ["--out afile: exists and is a file"]),
    (["3rrp", "--out", "mine"], ["--out mine: holds notes.txt"]),
], ids=["serial-robot", "unknown-robot", "grid-too-small", "grid-too-large", "missing-study", "study-key", "study-typo",
        "study-of-a-serial-robot", "out-is-a-file", "out-holds-other-files"])
def test_cli_mistakes_are_one_line_with_status_2(tmp_path, args, fragments):
    (tmp_path / "afile").write_text("x\n")
    (tmp_path / "mine").mkdir()
    (tmp_path / "mine" / "notes.txt").write_text("my notes\n")
    (tmp_path / "bad.toml").write_text(SMALL.replace("rays = 12\n", ""))
    (tmp_path / "typo.toml").write_text("centr = [0.0, 0.0]\n" + SMALL)
    (tmp_path / "serial.toml").write_text(SMALL.replace('robot = "3rrp"', 'robot = "rrp"'))
    done = cli("workspace", *args, cwd=tmp_path)
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert done.returncode == 2, done.stderr
    assert "Traceback" not in done.stderr and len(lines) == 1, done.stderr
    assert lines[0].startswith("robofmu workspace: ")
    for fragment in fragments:
        assert fragment in lines[0]
    assert not list(tmp_path.glob(".*.robofmu-*"))


def test_cli_argparse_mistake_keeps_the_usage_line(tmp_path):
    done = cli("workspace", "3rrp", "--grid", "fine", cwd=tmp_path)
    assert done.returncode == 2 and done.stderr.splitlines()[0].startswith("usage: robofmu workspace")
