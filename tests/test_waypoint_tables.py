"""Waypoints as a CSV table beside the robot's TOML (issue 22, point 3): the same reference as the
same rows written inline, checked rows with one-line errors naming file and line, the table part of
the robot's data (its hash) and carried by the FMU."""
from __future__ import annotations

import zipfile

import numpy as np
import pytest

from robofmu.components import robot_data_hash
from robofmu.components.blocks import make_block
from robofmu.components.robots import load_description
from robofmu.components.robots.description import DescriptionError, read
from robofmu.components.waypoint_table import read_table

from robot_files import set_key


def _with_table(copy_robot, text: str, name: str = "path.csv"):
    rows = load_description("planar2r").trajectory.parameters["waypoints"]
    path = copy_robot("planar2r", lambda d: set_key(d, "trajectory.waypoints", name))
    (path.parent / name).parent.mkdir(parents=True, exist_ok=True)
    (path.parent / name).write_text(text.format(*[v for row in rows for v in row]))
    return path, rows


def test_a_table_gives_the_same_reference_as_the_rows_inline(copy_robot):
    path, rows = _with_table(copy_robot, "x,y\n# FK(home), then two points\n{!r},{!r}\n{!r},{!r}\n\n{!r},{!r}\n")
    described = read(path)
    assert described.tables == ("path.csv",)
    from_table, inline = make_block(described, "trajectory"), make_block("planar2r", "trajectory")
    for block in (from_table, inline):
        block.configure()
    assert from_table.settings["waypoints"] == inline.settings["waypoints"]
    for t in np.linspace(0.0, 4.0, 41):
        for block in (from_table, inline):
            block.output(t)
        np.testing.assert_array_equal(from_table.values, inline.values)


def test_the_table_is_robot_data(copy_robot):
    path, _ = _with_table(copy_robot, "{!r},{!r}\n{!r},{!r}\n{!r},{!r}\n")
    described = read(path)
    before = robot_data_hash(described.path, described.urdf, described.tables)
    (path.parent / "path.csv").write_text((path.parent / "path.csv").read_text().replace("1.2", "1.25", 1))
    assert robot_data_hash(described.path, described.urdf, described.tables) != before


@pytest.mark.parametrize("text, problem", [
    ("x,y\n1.0,2.0\n1.0\n", r"path.csv, line 3: expected 2 finite numbers \(x, y\), got '1.0'"),
    ("a,b\n1.0,2.0\n3.0,4.0\n", r"path.csv, line 1: expected 2 numbers \(x, y\) or, first, the header x,y; got 'a,b'"),
    ("1.0,2.0\n3.0,nan\n", r"path.csv, line 2: expected 2 finite numbers \(x, y\), got '3.0,nan'"),
    ("1.0,2.0\n", r"path.csv: needs at least two waypoints, got 1"),
])
def test_a_malformed_table_is_refused_naming_file_and_line(tmp_path, text, problem):
    (tmp_path / "path.csv").write_text(text)
    with pytest.raises(ValueError, match=problem):
        read_table(tmp_path / "path.csv", ("x", "y"))


def test_a_missing_table_or_one_outside_the_robots_folder_is_refused(copy_robot):
    path = copy_robot("planar2r", lambda d: set_key(d, "trajectory.waypoints", "nowhere.csv"))
    with pytest.raises(DescriptionError, match=r"trajectory.waypoints: no such table .*nowhere.csv"):
        read(path)
    (path.parent.parent / "outside.csv").write_text("1,2\n3,4\n")
    path = copy_robot("planar2r", lambda d: set_key(d, "trajectory.waypoints", "../outside.csv"))
    with pytest.raises(DescriptionError, match="a table lives in the robot's folder"):
        read(path)


@pytest.mark.slow
def test_the_fmu_carries_the_table_and_follows_it(copy_robot, tmp_path):
    from robofmu.system.fmu import FMUInstance
    from robofmu.system.packaging.build import build

    path, _ = _with_table(copy_robot, "x,y\n{!r},{!r}\n{!r},{!r}\n{!r},{!r}\n", name="tables/path.csv")
    (fmu,) = build(path, tmp_path / "fmus", blocks=["trajectory"], log=lambda *_: None)
    with zipfile.ZipFile(fmu) as archive:
        assert "resources/robot/tables/path.csv" in archive.namelist()
    instance = FMUInstance(fmu, "trajectory")
    instance.initialize()
    inline = make_block("planar2r", "trajectory")
    inline.configure()
    for k in range(1, 6):
        instance.do_step((k - 1) * 0.5, 0.5)
        inline.output(k * 0.5)
        assert instance.get("x_ref") == pytest.approx(list(inline.get("x_ref")), abs=0.0)
    instance.close()
