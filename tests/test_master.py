"""The master: refusals that name blocks and variables, the chess loop, failures that keep results."""
import numpy as np
import pytest

from robofmu.components.robot import Robot
from robofmu.system import experiment
from robofmu.system.diagram import BlockSpec, System
from robofmu.system.master import DiagramError, Master, Result, SimulationError
from robofmu.system.reference import reference_run

LOOP = ["trajectory.x_ref -> ik.x_ref", "trajectory.xd_ref -> ik.xd_ref", "trajectory.xdd_ref -> ik.xdd_ref",
        "ik.q_ref -> controller.q_ref", "ik.qd_ref -> controller.qd_ref", "ik.qdd_ref -> controller.qdd_ref",
        "plant.q -> controller.q", "plant.qd -> controller.qd", "controller.tau -> plant.tau",
        "trajectory.grip -> controller.grip", "trajectory.grip -> plant.grip"]


def chess(fmu_dir, wires=LOOP, **params):
    blocks = [BlockSpec(b, f"{b}.fmu", params.get(b, {})) for b in ("trajectory", "ik", "controller", "plant")]
    return System(blocks, list(wires), fmu_dir=fmu_dir, name="test", stop_time=0.05, step=1e-3)


def refusal(system) -> str:
    with pytest.raises(DiagramError) as info:
        Master(system).check()
    return str(info.value)


def test_missing_and_invalid_fmus_are_refused(fmu_dir, tmp_path):
    bad = tmp_path / "ik.fmu"
    bad.write_bytes(b"not a zip")
    for name in ("trajectory", "controller", "plant"):
        (tmp_path / f"{name}.fmu").write_bytes((fmu_dir / f"{name}.fmu").read_bytes())
    s = chess(tmp_path)
    s.blocks.append(BlockSpec("plant2", "missing/plant.fmu"))
    text = refusal(s)
    assert f"block 'plant2': FMU {tmp_path / 'missing/plant.fmu'} does not exist (run `robofmu build`)" in text
    assert f"block 'ik': {bad} is not a valid FMU" in text


@pytest.mark.parametrize("wire, message", [
    ("ik.q_reff -> controller.q_ref", "ik has no variable 'q_reff'"),
    ("ik.q_ref -> controller.torque", "controller has no variable 'torque'"),
    ("robot.q -> controller.q", "no block 'robot'"),
    ("controller.q_ref -> plant.tau", "controller.q_ref[1] is a input, not an output"),
    ("plant.q -> ik.q_ref", "ik.q_ref[1] is a output, not an input"),
    ("trajectory.grip -> plant.tau[1]", "connection trajectory.grip -> plant.tau[1]: type mismatch (Boolean -> Real)"),
    ("plant.qd -> controller.qd_ref", None),                    # same unit: accepted (driven twice, see below)
    ("plant.qd[1] -> controller.q[1]", "unit mismatch (rad/s -> rad)"),
    ("trajectory.x_ref -> controller.q", "3 source variables for 4 inputs"),
])
def test_bad_connections_are_refused_naming_them(fmu_dir, wire, message):
    text = refusal(chess(fmu_dir.parent / "chess", LOOP + [wire]))
    if message:
        assert message in text
    else:
        assert "input controller.qd_ref[1] is driven twice: by ik.qd_ref[1] and plant.qd[1]" in text


def test_algebraic_loop_through_feedthrough_is_refused(fmu_dir):
    # ik -> controller -> ik: both have direct feedthrough (the plant breaks the usual loop)
    wires = [w for w in LOOP if w != "trajectory.x_ref -> ik.x_ref"] + ["controller.tau[1] -> ik.x_ref[1]"]
    text = refusal(chess(fmu_dir, wires))
    assert "algebraic loop through direct feedthrough: " in text
    loop = text.split("algebraic loop through direct feedthrough: ")[1].splitlines()[0]
    nodes = loop.split(" -> ")
    assert nodes[0] == nodes[-1] and "controller.tau[1]" in nodes and any(n.startswith("ik.q") for n in nodes)


def test_unknown_parameter_is_refused(fmu_dir):
    text = refusal(chess(fmu_dir, controller={"kpp": 1.0}, plant={"q": [0, 0, 0, 0]}))
    assert "block 'controller': unknown parameter 'kpp'" in text
    assert "block 'plant': 'q' is a output, not a parameter" in text


def test_unconnected_input_is_a_warning(fmu_dir):
    warnings = Master(chess(fmu_dir, [w for w in LOOP if "grip" not in w])).check()
    assert "input controller.grip is not connected: it keeps its start value false" in warnings
    assert "input plant.grip is not connected: it keeps its start value false" in warnings
    assert len(warnings) == 2


def test_evaluation_order_follows_feedthrough(fmu_dir):
    m = Master(chess(fmu_dir))
    assert m.check() == []
    assert m.order == ["trajectory", "ik", "plant", "controller"]


def test_chess_pd_keeps_the_tcp_within_1_mm(fmu_dir, tmp_path):
    """Acceptance: the controller's model exact, 1 ms steps, the whole 13 s task."""
    s = experiment.load("chess-pd", fmu_dir=fmu_dir.parent)
    result = Master(s).run(csv_path=tmp_path / "r.csv")
    robot = Robot("chess")
    q, x = result.vector("plant.q"), result.vector("trajectory.x_ref")
    tcp = np.array([robot.fk(qi) for qi in q])
    err = np.linalg.norm(tcp - x, axis=1)
    assert len(result.time) == 13001 and result.time[-1] == pytest.approx(13.0)
    assert err.max() < 5e-5                     # the acceptance asks for 1 mm; observed 0.016 mm
    # and against the monolithic reference (continuous controller), which tracks exactly
    ref = reference_run(s, result.time)
    np.testing.assert_allclose(ref.vector("tcp.x"), x, atol=1e-9)
    assert np.linalg.norm(tcp - ref.vector("tcp.x"), axis=1).max() < 5e-5
    # every output of every block is recorded, at every communication point
    for col in ["trajectory.x_ref[3]", "trajectory.grip", "ik.qdd_ref[4]", "ik.reachable", "controller.tau[2]",
                "plant.qd[4]"]:
        assert col in result.columns
    assert result["trajectory.grip"][6000] == 1.0 and result["trajectory.grip"][5999] == 0.0
    on_disk = Result.from_csv(tmp_path / "r.csv")
    assert on_disk.columns == result.columns
    np.testing.assert_array_equal(on_disk.data, result.data)


def test_gauss_seidel_has_no_delay_jacobi_one_step(fmu_dir):
    s = experiment.load("chess-pd", fmu_dir=fmu_dir.parent)
    gs = Master(s).run(stop_time=0.2)
    ja = Master(s).run(stop_time=0.2, algorithm="jacobi")
    x = gs.vector("trajectory.x_ref")
    # Gauss-Seidel: the IK output at t is the IK of the trajectory at t
    from robofmu.components.ik import make_ik
    ik = make_ik(Robot("chess"))
    for k in (50, 100, 200):
        np.testing.assert_allclose(gs.vector("ik.q_ref")[k], ik.position(x[k]), atol=1e-12)
        np.testing.assert_allclose(ja.vector("ik.q_ref")[k], ik.position(ja.vector("trajectory.x_ref")[k - 1]),
                                   atol=1e-12)


def test_mid_run_failure_names_block_time_and_keeps_results(fmu_dir, tmp_path):
    # kp h^2 = 10 > 4: the sampled loop is unstable and the plant state overflows
    s = experiment.load("chess-pd", fmu_dir=fmu_dir.parent)
    s.block("controller").parameters.update(kp=1e7, kd=0.0)
    csv = tmp_path / "results.csv"
    with pytest.raises(SimulationError) as info:
        Master(s).run(stop_time=2.0, csv_path=csv)
    err = info.value
    assert err.block == "plant"
    assert 0.01 < err.time < 2.0
    text = str(err)
    assert f"plant: fmi2DoStep failed at t = {err.time:.9g} s" in text
    assert "became non-finite during the step from t =" in text and "(joint" in text
    kept = Result.from_csv(csv)
    assert len(kept.time) == len(err.result.time) > 10
    assert kept.time[-1] == pytest.approx(err.time)        # the failing point's exchange is recorded
    np.testing.assert_array_equal(kept.data, err.result.data)


def test_failed_initialization_names_block_and_parameter(fmu_dir):
    s = experiment.load("chess-pd", fmu_dir=fmu_dir.parent)
    s.block("plant").parameters["payload_mass"] = -1.0
    with pytest.raises(SimulationError) as info:
        Master(s).run(stop_time=0.1)
    assert info.value.block == "plant"
    assert "parameter payload_mass = -1 kg is invalid: must be >= 0" in str(info.value)


def test_experiment_files_resolve_robot_values(fmu_dir):
    pid = experiment.load("chess-pid", fmu_dir=fmu_dir.parent)
    assert pid.block("controller").parameters == {"kp": 600.0, "kd": 25.0, "ki": 75.0, "payload_mass": 0.03}
    assert experiment.load("chess-pd-unknown-pawn").block("controller").parameters["payload_mass"] == 0.0
    assert set(experiment.available()) >= {"chess-pd", "chess-pid", "chess-pd-unknown-pawn", "chess-pid-unknown-pawn"}
    with pytest.raises(ValueError, match="unknown experiment 'chess-pdq'; available: chess-pd"):
        experiment.load("chess-pdq")
