"""Joint losses (issue 30, point 3): viscous damping b, smooth Coulomb friction tau_c tanh(qd / v_s)
and rotor inertia (armature) in the plant and the controller.

References are independent of the robot model: Pinocchio models built here from the URDF files
(``pin.buildModelFromUrdf``) with the friction torque computed here, closed forms of the PD error
dynamics, and scipy's quadrature of the dissipated power.
"""
from __future__ import annotations

import math
import tomllib
from xml.etree import ElementTree

import numpy as np
import pinocchio as pin
import pytest
from scipy.integrate import simpson, solve_ivp

from robofmu.components.blocks import make_block
from robofmu.components.control import ComputedTorque
from robofmu.components.plant import JointLosses, Plant
from robofmu.components.robots import DescriptionError, load_description, load_model
from robofmu.components.robots.urdf import UrdfError, read_urdf

#: URDF robots of the package whose files live in their folder (copied and edited here).
OWN_URDF = ("planar2r", "rrp", "chess", "rpp")


def with_dynamics(copy_robot, robot: str, damping, friction, edit=None):
    """``robot``'s folder copied, ``<dynamics damping friction>`` written into each movable joint of
    its URDF (in document order), and ``[joints] urdf_dynamics = true``; returns the TOML's path and
    the movable joints' names."""
    def asked(data):
        data.setdefault("joints", {})["urdf_dynamics"] = True
        if edit is not None:
            edit(data)

    toml = copy_robot(robot, asked)
    urdf = toml.parent / tomllib.loads(toml.read_text())["urdf"]
    tree = ElementTree.parse(urdf)
    movable = [j for j in tree.getroot().findall("joint") if j.get("type") in ("revolute", "prismatic", "continuous")]
    for joint, b, c in zip(movable, damping, friction):
        for old in joint.findall("dynamics"):
            joint.remove(old)
        ElementTree.SubElement(joint, "dynamics", damping=repr(float(b)), friction=repr(float(c)))
    tree.write(urdf)
    return toml, [j.get("name") for j in movable]


def independent(toml):
    """Pinocchio's model of the copy's URDF, built here, its gravity the TOML's."""
    data = tomllib.loads(toml.read_text())
    model = pin.buildModelFromUrdf(str(toml.parent / data["urdf"]))
    gravity = data.get("gravity", {})
    model.gravity.linear = gravity.get("magnitude", 9.81) * np.array(gravity.get("direction", [0.0, 0.0, -1.0]))
    return model


def states(model, rng, count: int, scale: float):
    """``count`` states (q within the limits, qd of size ~``scale``, some within the tanh's knee)."""
    low = np.maximum(model.lowerPositionLimit, -1.0)
    high = np.minimum(model.upperPositionLimit, 1.0)
    for k in range(count):
        q = low + (high - low) * rng.random(model.nq)
        qd = rng.normal(size=model.nv) * (scale if k % 2 else 0.01 * scale)
        yield q, qd, rng.normal(size=model.nv)


# -- the URDF's <dynamics> -------------------------------------------------------------------------
def test_the_urdf_reader_gives_damping_and_friction(copy_robot):
    toml, names = with_dynamics(copy_robot, "rrp", [0.5, 0.25, 2.0], [0.1, 0.0, 3.0])
    urdf = read_urdf(toml.parent / "rrp.urdf")
    assert [(urdf.joints[n].damping, urdf.joints[n].friction) for n in names] == [(0.5, 0.1), (0.25, 0.0), (2.0, 3.0)]
    fixed = [j for j in urdf.joints.values() if j.type == "fixed"]
    assert all(j.damping == 0.0 and j.friction == 0.0 for j in fixed)        # none given: 0


def test_the_urdfs_dynamics_act_only_when_asked(copy_robot):
    """Without ``[joints] urdf_dynamics = true`` the URDF's <dynamics> are read (the reader gives
    them) but the joints' losses are the TOML's alone: zero here; with it, the URDF's numbers."""
    asked, names = with_dynamics(copy_robot, "rrp", [0.5, 0.25, 2.0], [0.1, 0.0, 3.0])
    data = tomllib.loads(asked.read_text())
    assert data["joints"]["urdf_dynamics"] is True
    plain = asked.parent / "plain.toml"
    plain.write_text(asked.read_text().replace("urdf_dynamics = true", "urdf_dynamics = false")
                     .replace('name = "rrp"', 'name = "plain"'))
    damping, friction, _ = load_model(plain).joint_losses()
    assert damping.tolist() == friction.tolist() == [0.0, 0.0, 0.0]
    damping, friction, _ = load_model(asked).joint_losses()
    assert damping.tolist() == [0.5, 0.25, 2.0] and friction.tolist() == [0.1, 0.0, 3.0]


@pytest.mark.parametrize("attribute, value, problem", [
    ("damping", "-0.5", "dynamics damping -0.5 is negative"),
    ("friction", "nan", "dynamics friction: 'nan' is not a finite number"),
    ("friction", "1 2", "dynamics friction: '1 2' is not 1 number"),
])
def test_the_urdf_reader_refuses_bad_dynamics(copy_robot, attribute, value, problem):
    toml, names = with_dynamics(copy_robot, "rrp", [0.0] * 3, [0.0] * 3)
    urdf = toml.parent / "rrp.urdf"
    tree = ElementTree.parse(urdf)
    tree.getroot().find(f"joint[@name='{names[1]}']/dynamics").set(attribute, value)
    tree.write(urdf)
    with pytest.raises(UrdfError) as info:
        read_urdf(urdf)
    text = str(info.value)
    assert text.startswith(f"{urdf}: joint {names[1]!r}: {problem}") and "\n" not in text


@pytest.mark.parametrize("robot", OWN_URDF)
def test_urdf_friction_changes_the_plant_as_pinocchio_says(copy_robot, robot):
    """The plant block's qdd (its FMI-free logic: the Plant's acceleration under the block's
    defaults) equals pin.aba on a model built here from the URDF, under tau - b qd - tau_c
    tanh(qd / v_s) computed here, at several states, to 1e-12 (relative to |qdd| + 1)."""
    n = load_model(robot).n
    rng = np.random.default_rng(7)
    b, c = rng.uniform(0.1, 2.0, n), rng.uniform(0.1, 3.0, n)
    toml, _ = with_dynamics(copy_robot, robot, b, c)
    block = make_block(load_description(toml), "plant")
    block.configure()
    v_s = block.get("friction_velocity")
    assert np.array_equal(block.get("damping"), b) and np.array_equal(block.get("friction"), c)
    assert np.all(v_s == 0.01)
    model = independent(toml)
    data = model.createData()
    worst, changed = 0.0, 0.0
    for q, qd, tau in states(model, rng, 8, 0.05):
        expected = pin.aba(model, data, q, qd, tau - b * qd - c * np.tanh(qd / v_s))
        got = block.plant.acceleration(np.concatenate([q, qd]), tau)
        worst = max(worst, float(np.max(np.abs(got - expected)) / (1.0 + np.max(np.abs(expected)))))
        changed = max(changed, float(np.max(np.abs(got - pin.aba(model, data, q, qd, tau)))))
    assert worst < 1e-12
    assert changed > 1e-2                                 # the losses do move qdd


def test_the_toml_overrides_the_urdf(copy_robot):
    """[joints.dynamics.<joint>] replaces the URDF's damping and friction of that joint (and gives
    its armature); the other joints keep the URDF's. The plant's and the controller's parameters
    start there."""
    def edit(data):
        data.setdefault("joints", {})["dynamics"] = {"joint2": {"damping": 7.0, "armature": 0.02}}
    toml, names = with_dynamics(copy_robot, "rrp", [0.5, 0.25, 2.0], [0.1, 0.2, 3.0], edit)
    assert names[1] == "joint2"
    assert load_description(toml).joint_dynamics == {"joint2": {"damping": 7.0, "armature": 0.02}}
    damping, friction, armature = load_model(toml).joint_losses()
    assert damping.tolist() == [0.5, 7.0, 2.0] and friction.tolist() == [0.1, 0.2, 3.0]
    assert armature.tolist() == [0.0, 0.02, 0.0]
    for kind in ("plant", "controller"):
        block = make_block(load_description(toml), kind)
        assert block.get("damping").tolist() == [0.5, 7.0, 2.0]
        assert block.get("armature").tolist() == [0.0, 0.02, 0.0]


@pytest.mark.parametrize("table, key, fragment", [
    ({"joint2": {"damping": -1.0}}, "joints.dynamics.joint2.damping", "must be >= 0, got -1.0"),
    ({"joint2": {"friction": math.inf}}, "joints.dynamics.joint2.friction", "must be a finite number"),
    ({"joint2": {"stiction": 1.0}}, "joints.dynamics.joint2.stiction", "unknown"),
])
def test_the_toml_refuses_bad_losses(copy_robot, table, key, fragment):
    toml = copy_robot("rrp", lambda d: d.setdefault("joints", {}).update(dynamics=table))
    with pytest.raises(DescriptionError) as info:
        load_description(toml)
    assert str(info.value).startswith(f"{toml}: {key}: ") and fragment in str(info.value)


def test_the_toml_refuses_a_joint_the_model_lacks(copy_robot):
    toml = copy_robot("rrp", lambda d: d.setdefault("joints", {}).update(dynamics={"elbow9": {"damping": 1.0}}))
    with pytest.raises(ValueError) as info:
        load_model(toml)
    assert str(info.value).startswith(f"{toml}: joints.dynamics.elbow9: no joint 'elbow9'")


# -- armature --------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot", ["rrp", "chess"])
def test_armature_adds_to_the_mass_matrix(copy_robot, robot):
    """With armature a: M(q) = crba(q) + diag(a) of an independent model without it (so Pinocchio's
    CRBA adds model.armature: checked, not assumed); the plant's qdd solves that M; the
    controller's inverse dynamics is M qdd + N with it; the kinetic energy 1/2 qd^T M qd."""
    n = load_model(robot).n
    armature = 0.01 * np.arange(1, n + 1)
    names = load_model(robot).joint_names
    toml = copy_robot(robot, lambda d: d.setdefault("joints", {}).update(
        dynamics={name: {"armature": float(a)} for name, a in zip(names, armature)}))
    plant = make_block(load_description(toml), "plant")
    plant.configure()
    controller_model = make_block(load_description(toml), "controller").robot
    model = independent(toml)
    data = model.createData()
    rng = np.random.default_rng(3)
    for q, qd, tau in states(model, rng, 5, 1.0):
        crba = pin.crba(model, data, q)
        M = np.triu(crba) + np.triu(crba, 1).T + np.diag(armature)
        nle = pin.nonLinearEffects(model, data, q, qd)
        assert np.max(np.abs(plant.robot.mass_matrix(q) - M)) < 1e-12
        qdd = np.linalg.solve(M, tau - nle)
        assert np.max(np.abs(plant.plant.acceleration(np.concatenate([q, qd]), tau) - qdd)) < 1e-10
        assert np.max(np.abs(controller_model.inverse_dynamics(q, qd, qdd) - tau)) < 1e-10
        assert abs(plant.robot.kinetic_energy(q, qd) - 0.5 * qd @ M @ qd) < 1e-12
        assert np.max(np.abs(np.diag(M) - np.diag(M - np.diag(armature)))) > 0.005


def test_armature_as_a_parameter_replaces_the_data():
    """The plant's ``armature[j]`` parameter sets its model's (another instance keeps its own)."""
    plant = make_block("chess", "plant")
    plant.set("armature", [0.5, 0.0, 0.0, 0.0])
    plant.configure()
    q = plant.robot.configuration("home")
    bare = load_model("chess").mass_matrix(q)
    assert plant.robot.mass_matrix(q)[0, 0] - bare[0, 0] == pytest.approx(0.5, abs=1e-12)
    assert np.array_equal(plant.robot.mass_matrix(q)[1:, 1:], bare[1:, 1:])


# -- energy ----------------------------------------------------------------------------------------
@pytest.mark.parametrize("robot", ["chess", "rrp"])
def test_the_energy_decays_at_the_dissipated_power(robot):
    """Without gravity and effort, E(T) - E(0) = -int_0^T qd^T (b qd + tau_c tanh(qd / v_s)) dt.
    E from an independent Pinocchio model with the armature (1/2 qd^T (M + diag a) qd), the
    integral by Simpson's rule over the recorded qd; to 1e-6 of the energy lost."""
    plant = make_block(robot, "plant")
    n = plant.robot.n
    b, c, v_s, a = 0.02 * np.ones(n), 0.01 * np.ones(n), 0.05 * np.ones(n), 0.001 * np.ones(n)
    for name, value in (("g", 0.0), ("damping", b), ("friction", c), ("friction_velocity", v_s), ("armature", a),
                        ("qd0", 0.8 * np.ones(n)), ("max_substep", 2.5e-4)):
        plant.set(name, value)
    plant.configure()
    model = load_model(robot).model.copy()          # the package's reduced model, armature set here
    model.armature = a
    data = model.createData()

    def energy(q, qd):
        crba = pin.crba(model, data, q)
        return 0.5 * qd @ (np.triu(crba) + np.triu(crba, 1).T) @ qd

    h, steps = 1e-3, 600
    plant.output(0.0)
    qs, qds = [plant.get("q")], [plant.get("qd")]
    for k in range(steps):
        plant.advance(k * h, h)
        plant.output((k + 1) * h)
        qs.append(plant.get("q"))
        qds.append(plant.get("qd"))
    qds = np.array(qds)
    power = np.sum(qds * (b * qds + c * np.tanh(qds / v_s)), axis=1)
    lost = simpson(power, dx=h)
    change = energy(qs[-1], qds[-1]) - energy(qs[0], qds[0])
    assert lost > 0.05 * energy(qs[0], qds[0])                # a real loss, not a rounding
    assert abs(change + lost) < 1e-6 * lost


# -- the controller --------------------------------------------------------------------------------
def closed_loop(plant, controller, reference, t_end: float, times):
    """The continuous-time loop through the FMI-free blocks (the controller evaluated at every
    stage, no hold), integrated by DOP853 to rtol 1e-12; the tracking error q_ref - q at ``times``."""
    def rhs(t, x):
        q_ref, qd_ref, qdd_ref = reference(t)
        plant.set_continuous_state(x)
        for name, value in (("q_ref", q_ref), ("qd_ref", qd_ref), ("qdd_ref", qdd_ref), ("q", x[:plant.robot.n]),
                            ("qd", x[plant.robot.n:])):
            controller.set(name, value)
        controller.output(t)
        plant.set("tau", controller.get("tau"))
        return plant.derivative(t)

    solution = solve_ivp(rhs, (0.0, t_end), plant.continuous_state(), method="DOP853", t_eval=times,
                         rtol=1e-12, atol=1e-13)
    assert solution.success
    n = plant.robot.n
    return np.array([reference(t)[0] for t in times]) - solution.y[:n].T


def blocks(robot, losses: dict, known: float = 1.0, q0=None, qd0=None):
    plant, controller = make_block(robot, "plant"), make_block(robot, "controller")
    for name, value in losses.items():
        plant.set(name, value)
        controller.set(name, value)
    controller.set("loss_compensation", known)
    if q0 is not None:
        plant.set("q0", q0)
    if qd0 is not None:
        plant.set("qd0", qd0)
    plant.configure()
    controller.configure()
    return plant, controller


@pytest.mark.parametrize("robot", ["planar2r", "chess"])
def test_known_losses_are_cancelled(robot):
    """Computed torque that knows the damping, friction and armature leaves the error dynamics
    e'' + kd e' + kp e = 0 of the rigid arm: the tracking error equals the lossless loop's to
    1e-9 rad over 0.5 s (both continuous loops through the FMI-free blocks); with the losses
    unknown (loss_compensation = 0) it does not."""
    n = load_model(robot).n
    home = load_model(robot).configuration("home")

    def reference(t):
        w = 2.0 * np.arange(1, n + 1)
        return home + 0.2 * np.sin(w * t), 0.2 * w * np.cos(w * t), -0.2 * w * w * np.sin(w * t)

    losses = {"damping": 0.3 * np.ones(n), "friction": 0.2 * np.ones(n), "friction_velocity": 0.05 * np.ones(n),
              "armature": 0.01 * np.ones(n)}
    zero = {key: np.zeros(n) for key in ("damping", "friction", "armature")}
    times = np.linspace(0.0, 0.5, 26)
    start = {"q0": home + 0.05, "qd0": 0.4 * np.arange(1, n + 1)}          # an initial error to decay
    known = closed_loop(*blocks(robot, losses, 1.0, **start), reference, 0.5, times)
    rigid = closed_loop(*blocks(robot, zero, 1.0, **start), reference, 0.5, times)
    unknown = closed_loop(*blocks(robot, losses, 0.0, **start), reference, 0.5, times)
    assert np.max(np.abs(known - rigid)) < 1e-9
    assert np.max(np.abs(unknown - rigid)) > 1e-4


def one_joint_robot(tmp_path, friction: float, damping: float = 0.0):
    """A one-joint arm turning about the vertical z (gravity along -z: no torque), a link of mass
    2 kg with its centre 0.3 m out and izz 0.01 kg m^2: M = 0.01 + 2 (0.3)^2 = 0.19 kg m^2."""
    (tmp_path / "spinner.urdf").write_text(f"""<robot name="spinner">
  <link name="base"/>
  <link name="arm"><inertial><origin xyz="0.3 0 0"/><mass value="2.0"/>
    <inertia ixx="0.001" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <link name="tip"><inertial><mass value="0.0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/>
    </inertial></link>
  <joint name="turn" type="continuous"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
    <dynamics damping="{damping!r}" friction="{friction!r}"/></joint>
  <joint name="tool" type="fixed"><parent link="arm"/><child link="tip"/><origin xyz="0.6 0 0"/></joint>
</robot>
""")
    toml = tmp_path / "spinner.toml"
    toml.write_text("""name = "spinner"
summary = "one joint about the vertical"
urdf = "spinner.urdf"
blocks = ["controller", "plant"]
default_gains = "pd"
[task]
frame = "tip"
coordinates = ["x", "y"]
[joints]
urdf_dynamics = true
[configurations]
home = [0.0]
[gains.pd]
kp = 400.0
kd = 40.0
""")
    return toml


def test_unknown_friction_leaves_the_steady_error(tmp_path):
    """A PD on a joint of constant M = 0.19 kg m^2 tracking q_ref = v t at v = 1 rad/s (qd / v_s =
    100: tanh(qd / v_s) is 1 to the last bit) against Coulomb friction tau_c = 0.5 N.m unknown to
    the controller: e'' + kd e' + kp e = tau_c / M from rest error, so
    e(t) = e_ss (1 + (r2 exp(r1 t) - r1 exp(r2 t)) / (r1 - r2)) with e_ss = tau_c / (M kp); the
    continuous loop to 1e-9 e_ss, the sampled one (1 ms, held torque) settles at e_ss to 1e-9 e_ss
    (a constant error holds a constant torque: the hold changes nothing in the steady state)."""
    toml = one_joint_robot(tmp_path, friction=0.5)
    M, kp, kd, tau_c, v = 0.19, 400.0, 40.0, 0.5, 1.0
    assert load_model(toml).mass_matrix(np.zeros(1))[0, 0] == pytest.approx(M, rel=1e-14)
    e_ss = tau_c / (M * kp)
    roots = np.roots([1.0, kd - 1e-3, kp])           # kd nudged: distinct roots of the closed form
    plant, controller = blocks(load_description(toml), {}, 0.0, qd0=[v])
    controller.set("kd", kd - 1e-3)
    controller.configure()

    def reference(t):
        return np.array([v * t]), np.array([v]), np.array([0.0])

    times = np.linspace(0.0, 1.5, 16)
    error = closed_loop(plant, controller, reference, 1.5, times)[:, 0]
    r1, r2 = roots
    closed_form = np.real(e_ss * (1.0 + (r2 * np.exp(r1 * times) - r1 * np.exp(r2 * times)) / (r1 - r2)))
    assert np.max(np.abs(error - closed_form)) < 1e-9 * e_ss
    assert error[-1] == pytest.approx(e_ss, rel=1e-6)

    plant, controller = blocks(load_description(toml), {}, 0.0, qd0=[v])     # sampled: held torque
    h = 1e-3
    for k in range(2000):
        t = k * h
        for name, value in zip(("q_ref", "qd_ref", "qdd_ref"), reference(t)):
            controller.set(name, value)
        controller.set("q", plant.get("q"))
        controller.set("qd", plant.get("qd"))
        controller.output(t)
        plant.set("tau", controller.get("tau"))
        plant.advance(t, h)
        plant.output(t + h)
    assert v * 2.0 - plant.get("q")[0] == pytest.approx(e_ss, rel=1e-9)
    # known to the controller: no error left
    plant, controller = blocks(load_description(toml), {}, 1.0, qd0=[v])
    error = closed_loop(plant, controller, reference, 1.5, times)[:, 0]
    assert np.max(np.abs(error)) < 1e-9 * e_ss


def test_the_controller_adds_the_losses_it_knows():
    """ComputedTorque's effort with losses = without + b qd + tau_c tanh(qd / v_s), exactly as
    JointLosses computes it, at the measured qd; loss_compensation scales b and tau_c."""
    robot = load_model("ur5")
    rng = np.random.default_rng(5)
    losses = JointLosses.of(rng.uniform(0, 1, 6), rng.uniform(0, 1, 6), 0.02)
    q, qd, q_ref, qd_ref, qdd_ref = (rng.normal(size=6) for _ in range(5))
    bare = ComputedTorque(robot, 400.0, 40.0).torque(q_ref, qd_ref, qdd_ref, q, qd)
    lossy = ComputedTorque(robot, 400.0, 40.0, losses=losses).torque(q_ref, qd_ref, qdd_ref, q, qd)
    expected = losses.damping * qd + losses.friction * np.tanh(qd / 0.02)
    assert np.max(np.abs(lossy - bare - expected)) < 1e-12
    controller = make_block("ur5", "controller")
    for name, value in (("damping", losses.damping), ("friction", losses.friction), ("friction_velocity", np.full(6, 0.02)),
                        ("loss_compensation", 0.5), ("q_ref", q_ref), ("qd_ref", qd_ref), ("qdd_ref", qdd_ref),
                        ("q", q), ("qd", qd)):
        controller.set(name, value)
    controller.configure()
    controller.output(0.0)
    assert np.max(np.abs(controller.get("tau") - bare - 0.5 * expected)) < 1e-12


# -- parameters ------------------------------------------------------------------------------------
@pytest.mark.parametrize("kind", ["plant", "controller"])
@pytest.mark.parametrize("name, value, message", [
    ("damping", [0.0, -1.0, 0.0], "parameter damping[2] = -1 is invalid: must be finite and >= 0"),
    ("friction", [0.0, 0.0, math.nan], "parameter friction[3] = nan is invalid: must be finite and >= 0"),
    ("friction_velocity", [0.01, 0.0, 0.01], "parameter friction_velocity[2] = 0 is invalid: must be finite and > 0"),
    ("armature", [-0.1, 0.0, 0.0], "parameter armature[1] = -0.1 is invalid: must be finite and >= 0"),
    ("armature", [math.inf, 0.0, 0.0], "parameter armature[1] = inf is invalid: must be finite"),
])
def test_bad_loss_parameters_are_refused_by_name(kind, name, value, message):
    block = make_block("rrp", kind)
    block.set(name, value)
    with pytest.raises(ValueError) as info:
        block.configure()
    assert str(info.value) == message


def test_the_losses_are_declared_with_units():
    plant = make_block("rrp", "plant")                   # revolute, revolute, prismatic
    units = {v.name: v.unit for v in plant.variables}
    assert [units[f"damping[{j}]"] for j in (1, 3)] == ["N.m.s/rad", "N.s/m"]
    assert [units[f"friction[{j}]"] for j in (1, 3)] == ["N.m", "N"]
    assert [units[f"friction_velocity[{j}]"] for j in (1, 3)] == ["rad/s", "m/s"]
    assert [units[f"armature[{j}]"] for j in (1, 3)] == ["kg.m2", "kg"]
    controller = make_block("rrp", "controller")
    assert {"damping[1]", "friction[3]", "armature[2]", "loss_compensation"} <= set(controller.index)
    parallel = make_block("3rrp", "plant")              # a model without armature: losses only
    assert "damping[1]" in parallel.index and "armature[1]" not in parallel.index


def test_stiff_friction_shortens_the_substeps(tmp_path):
    """tau_c / v_s = 100 N.m.s/rad on M = 0.19 kg m^2 decays at 526 /s: RK4 needs h <= 2 / 526 s,
    so a 10 ms step takes ceil(0.01 x 526 / 2) = 3 sub-steps (not 1 of max_substep = 10 ms), and the
    joint released at 0.3 rad/s comes to rest; one sub-step per step chatters near rest instead."""
    toml = one_joint_robot(tmp_path, friction=0.5)
    robot = load_model(toml)
    plant = Plant(robot, [0.0], [0.3], max_substep=0.01, losses=JointLosses.of([0.0], [0.5], 0.005))
    rate = 0.5 / 0.005 / 0.19
    assert plant.substeps(0.01) == math.ceil(0.01 * rate / 2.0) == 3
    velocities = []
    for _ in range(100):
        plant.step(np.zeros(1), 0.01)
        velocities.append(plant.qd[0])
    velocities = np.array(velocities)
    assert np.all(velocities >= -1e-12) and np.max(np.abs(velocities[-10:])) < 1e-6
    stiff = Plant(robot, [0.0], [0.3], max_substep=0.01, losses=JointLosses.of([0.0], [0.5], 0.005))
    for k in range(100):                                 # one sub-step of 10 ms: unstable at rest
        stiff.step(np.zeros(1), 0.01, substeps=1)
        velocities[k] = stiff.qd[0]
    assert np.max(np.abs(velocities[-10:])) > 1e-4


# -- through the master ----------------------------------------------------------------------------
@pytest.mark.slow
def test_zero_losses_run_chess_pd_bit_for_bit(fmu_root, tmp_path):
    """chess-pd through the master for 0.5 s: the plant's and the controller's losses and armature
    set to 0 explicitly give the CSV of the run that leaves them at the data's (chess: none) byte
    for byte; the measured outputs are the state; damping unknown to the controller changes q."""
    from robofmu.system import experiment
    from robofmu.system.master import Master

    system = experiment.load("chess-pd", fmu_dir=fmu_root)
    zero = {f"{block}.{name}": [0.0] * 4 for block in ("plant", "controller") for name in ("damping", "friction",
                                                                                       "armature")}
    absent = Master(system).run(stop_time=0.5)
    explicit = Master(experiment.with_parameters(system, zero)).run(stop_time=0.5)
    assert absent.to_csv(tmp_path / "absent.csv").read_bytes() == explicit.to_csv(tmp_path / "zero.csv").read_bytes()
    assert np.array_equal(absent.vector("plant.q_measured"), absent.vector("plant.q"))
    assert np.array_equal(absent.vector("plant.qd_measured"), absent.vector("plant.qd"))
    lossy = Master(experiment.with_parameters(system, {"plant.damping": [0.05] * 4,
                                                       "controller.loss_compensation": 0.0})).run(stop_time=0.5)
    assert np.max(np.abs(lossy.vector("plant.q") - absent.vector("plant.q"))) > 1e-6
