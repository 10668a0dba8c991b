"""One wording for an unknown key in every TOML reader: the keys known, and the nearest one."""
from __future__ import annotations

import pytest

from robofmu.components.blocks import make_block
from robofmu.components.robots import DescriptionError
from robofmu.components.robots.description import read
from robofmu.components.unknown_names import unknown_key
from robofmu.system.experiment import ExperimentError, load
from misuse import assert_refused
from robot_files import set_key


def test_the_nearest_known_key_is_named_where_one_is_close():
    assert unknown_key("stoptime", ["step", "stop_time", "name"]) == \
        "unknown key (known: name, step, stop_time); did you mean 'stop_time'?"
    assert unknown_key("colour", ["kp", "kd"]) == "unknown key (known: kd, kp)"


def test_a_robot_description_names_the_gain_it_meant(copy_robot):
    path = copy_robot("rrp", lambda data: set_key(data, "gains.pd.kpp", 100.0))
    with pytest.raises(DescriptionError) as refused:
        read(path)
    assert str(refused.value).endswith("gains.pd.kpp: unknown key (known: kd, ki, kp); did you mean 'kp'?")


def test_an_experiment_file_names_the_key_it_meant(tmp_path):
    path = tmp_path / "typo.toml"
    path.write_text('name = "typo"\nbase = "chess-loop"\nstoptime = 3.0\n')
    with pytest.raises(ExperimentError) as refused:
        load(path)
    message = str(refused.value)
    assert message.startswith(f"{path}: stoptime: unknown key (known: ") and "stop_time" in message
    assert message.endswith("; did you mean 'stop_time'?")


@pytest.mark.parametrize("argv, line", [
    (["run", "chess-pd", "--set", "plant.q00=1"],
     "robofmu run: --set plant.q00=1: the diagram cannot run: block 'plant': unknown parameter 'q00' in plant.fmu; "
     "did you mean 'q0'?"),
    (["run", "chess-pd", "--set", "controller.sample_time=0.0025"],
     "robofmu run: --set controller.sample_time=0.0025: the diagram cannot run: block 'controller': sample_time = "
     "0.0025 s is not a whole multiple of the base step 0.001 s"),
    (["sweep", "chess-pd", "--vary", "controller.kpp=1,2"],
     "robofmu sweep: --vary controller.kpp: unknown parameter 'kpp' of block 'controller' (controller.fmu); "
     "did you mean 'kp'?"),
], ids=["set-parameter", "set-sample-time", "vary-parameter"])
def test_a_mistyped_parameter_on_the_command_line_is_told_at_its_option(fmu_root, tmp_path, capfd, argv, line):
    out = tmp_path / "out"
    assert assert_refused(capfd, [*argv, "--fmus", fmu_root, "--out", out, "--stop-time", "0.01"]) == line
    assert not out.exists()


def test_a_mistyped_parameter_in_an_experiment_file_is_told_at_the_file(fmu_root, tmp_path, capfd):
    path = tmp_path / "typo.toml"
    path.write_text('name = "typo"\nbase = "chess-pd"\n[parameters.controller]\nkpp = 100.0\n')
    assert assert_refused(capfd, ["run", path, "--fmus", fmu_root, "--out", tmp_path / "out"]) == (
        f"robofmu run: {path}: the diagram cannot run: block 'controller': unknown parameter 'kpp' in "
        "controller.fmu; did you mean 'kp'?")


def test_a_profile_parameter_in_a_robot_description_names_the_one_it_meant(copy_robot):
    path = copy_robot("rrp", lambda data: set_key(data, "trajectory.lenght", 0.1))
    with pytest.raises(DescriptionError) as refused:
        make_block(read(path), "trajectory")
    assert str(refused.value).endswith("(known: a_max, length, v_max); did you mean 'length'?")
