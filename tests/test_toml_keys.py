"""One wording for an unknown key in every TOML reader: the keys known, and the nearest one."""
from __future__ import annotations

import pytest

from robofmu.components.robots import DescriptionError
from robofmu.components.robots.description import read
from robofmu.components.toml_keys import unknown_key
from robofmu.system.experiment import ExperimentError, load
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
