"""The step's figure (:func:`plot_comparison`: the co-simulated response against the
predictions, the difference in % of the amplitude, the efforts) and the report's cases
(:func:`demo_cases`: every gain set of a robot run, compared and plotted)."""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

from robofmu.system import defaults
from robofmu.system.stepresponse.comparison import Comparison, compare
from robofmu.system.stepresponse.experiment import Robot, cosimulate_step, steppable

__all__ = ["demo_cases", "plot_comparison"]


def _display(unit: str) -> str:
    """A unit for a figure: products with a middle dot (N.m -> N·m)."""
    return unit.replace(".", "\u00b7")


def _groups(joints: Sequence[int], units: Sequence[str]) -> dict[str, list[int]]:
    """Joints (from 1) grouped by unit, in order of first appearance."""
    groups: dict[str, list[int]] = {}
    for j in joints:
        groups.setdefault(units[j - 1], []).append(j)
    return groups


def plot_comparison(comparison: Comparison, out_dir: str | Path, name: str | None = None) -> Path:
    """Figure of the co-simulated step against the continuous, c2d and sampled-data predictions
    (the sampled-data loop at the controller's sample time and delay, where the run has them).

    One panel of q - q0 per position unit of the stepped joints (rad, m) with the co-simulated
    responses and the predictions; then co-simulated minus predicted, in % of each joint's
    amplitude, with the 1 % band; then one panel of the actuator efforts per effort unit (N.m, N).
    Labels and units come from the robot model.

    Parameters
    ----------
    comparison : Comparison
    out_dir : str or Path
        Folder for the PNG (created).
    name : str, optional
        File stem; default from robot, gains, communication step and stepped joints.

    Returns
    -------
    Path
        The PNG written.
    """
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    c = comparison
    g = c.gains
    if name is None:
        name = (f"step_{c.robot}_kp{g['kp']:g}_kd{g['kd']:g}_ki{g['ki']:g}_h{c.h * 1e3:g}ms_"
                f"j{'-'.join(map(str, c.joints))}")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    position_groups = _groups(c.joints, c.joint_units)
    effort_groups = _groups(range(1, len(c.effort_units) + 1), c.effort_units)
    ratios = [3] * len(position_groups) + [2] + [2] * len(effort_groups)
    fig, axes = plt.subplots(len(ratios), 1, figsize=(8, 1.6 * sum(ratios) / 2 + 1.5), sharex=True,
                             gridspec_kw={"height_ratios": ratios}, squeeze=False)
    axes = axes[:, 0]
    styles = {"continuous": dict(color="k", lw=1.2, ls="-"),
              "zoh": dict(color="tab:orange", lw=0, marker=".", ms=3),
              "sampled": dict(color="tab:blue", lw=1.2, ls="--")}
    column = {j: k for k, j in enumerate(c.joints)}
    for ax, (unit, joints) in zip(axes, position_groups.items()):
        for j in joints:
            ax.plot(c.time, c.response[:, column[j]], lw=2.5, alpha=0.45,
                    label=f"co-simulated {c.symbol(j)} ({c.amplitudes[column[j]]:+g} {_display(unit)})")
        for model in c.predictions:
            drawn = set()
            for j in joints:
                amplitude = float(c.amplitudes[column[j]])
                if amplitude in drawn:
                    continue
                ax.plot(c.time, c.predictions[model][:, column[j]], **styles.get(model, {}),
                        label=c.model_text(model) if not drawn else None)
                drawn.add(amplitude)
        for amplitude in {float(c.amplitudes[column[j]]) for j in joints}:
            ax.axhline(amplitude, color="grey", lw=0.6)
        ax.set_ylabel(f"q - q0 ({_display(unit)})")
        ax.legend(fontsize=8)
    deviation_axis = axes[len(position_groups)]
    for model in c.predictions:
        for k, j in enumerate(c.joints):
            percent = (c.response[:, k] - c.predictions[model][:, k]) / abs(c.amplitudes[k]) * 100.0
            deviation_axis.plot(c.time, percent, color=styles.get(model, {}).get("color"),
                                lw=0.9 if model != "continuous" else 0.7,
                                ls=":" if model == "continuous" else "-", alpha=0.85,
                                label=f"vs {model} (max {c.max_deviation(model):.2f} %)" if k == 0 else None)
    for sign in (-1.0, 1.0):
        deviation_axis.axhline(sign, color="grey", ls=":", lw=0.8)
    deviation_axis.plot([], [], color="grey", ls=":", label="1 % of the amplitude")
    deviation_axis.set_ylabel("co-sim - prediction\n(% of amplitude)")
    deviation_axis.legend(fontsize=7, ncol=2)
    effort = c.effort()
    for ax, (unit, joints) in zip(axes[len(position_groups) + 1:], effort_groups.items()):
        for j in joints:
            ax.plot(c.time, effort[:, j - 1], lw=1.0, label=f"tau{j} ({c.symbol(j)})")
        ax.set_ylabel(f"effort ({_display(unit)})")
        ax.legend(fontsize=7, ncol=min(4, len(joints)))
    rate = "" if c.sample_time is None else f", controller every {c.sample_time * 1e3:g} ms, d = {c.delay_steps}"
    axes[0].set_title(f"{c.robot}: step {c.step_text()}\nkp {g['kp']:.4g}, kd {g['kd']:.4g}, "
                      f"ki {g['ki']:.4g}; h = {c.h * 1e3:g} ms{rate} ({c.algorithm})", fontsize=10)
    axes[-1].set_xlabel("t (s)")
    for ax in axes:
        ax.grid(alpha=0.3)
    from robofmu.system.plots import save_figure

    return save_figure(fig, out / f"{name}.png", dpi=120)


def demo_cases(robot: Robot, fmu_dir: str | Path, out_dir: str | Path, h: float = defaults.STEP_SIZE,
               stop_time: float = defaults.STOP_TIME) -> list[tuple[str, tuple[Comparison, Path]]]:
    """The default step of ``robot`` under each gain set of its description, compared and plotted.

    Every joint steps by its :data:`~.experiment.DEFAULT_AMPLITUDE` from the ``home`` configuration.

    Parameters
    ----------
    robot : str, Path or RobotDescription
        A robot with a controller and a plant block: by name, robot TOML path or description.
    fmu_dir : str or Path
        Folder holding ``<name>/{controller,plant}.fmu``, ``<name>`` the robot's name.
    out_dir : str or Path
        Folder for the figures, ``step_<name>_<gain set>.png`` (created).
    h, stop_time : float
        Communication step and stop time (s).

    Returns
    -------
    list of (str, (Comparison, Path))
        One per gain set, in the description's order: the label ``"<set>: kp .., kd .., ki .."``
        and the comparison with its figure.
    """
    cases = []
    description = steppable(robot)
    for name, gains in description.gains.items():
        comparison = compare(cosimulate_step(fmu_dir, gains.kp, gains.kd, gains.ki, robot=description, h=h,
                                             stop_time=stop_time))
        figure = plot_comparison(comparison, out_dir, name=f"step_{description.name}_{name}")
        cases.append((f"{name}: kp {gains.kp:g}, kd {gains.kd:g}, ki {gains.ki:g}", (comparison, figure)))
    return cases
