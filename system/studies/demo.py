"""`robofmu demo`: the flagship studies of the source documents, reproduced and extended.

What runs is data (``system/studies/demo.toml``, read typed by :mod:`.plan`): sections of
experiments with their figures and tables, the accuracy study against the monolithic reference,
and the step responses. This module knows no robot.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np

from robofmu.system import defaults, plots
from robofmu.system.analysis import markdown_table
from robofmu.system.experiment import load
from robofmu.system.run import run_experiment, summary_line
from robofmu.system.studies.plan import (AccuracyStudy, ExperimentSection, InteropSection, RobustnessStudy,
                                         StepResponses, WorkspaceEntry, read_plan)
from robofmu.system.studies.replica import InProcessDiagram
from robofmu.system.studies.tables import bangbang_table, compare_with_seed, dynamics_table
from robofmu.system.units import printed, small
from robofmu.system.usage import OutputFolder, owned_by


def _say(text: str) -> None:
    print(text, file=sys.stderr)


def experiment_section(section: ExperimentSection, out: Path, fmu_dir) -> tuple[list[str], list[list]]:
    """One section: its experiments, figures, and the tables it asks for; returns the markdown
    lines and its rows of the summary table."""
    runs = {name: run_experiment(name, out / name, fmu_dir=fmu_dir) for name in section.experiments}
    lines = [f"## {section.title}", "", section.text, ""]
    summary = []
    for name, run in runs.items():
        m = run.metrics
        worst = int(m.max_error.argmax())
        factor, unit = small(m.joint_units[worst])
        summary.append([name, f"{m.max_error[worst] * factor:.4f} {unit} (q{worst + 1})",
                        "—" if m.tcp_error is None else f"{m.tcp_error.max() * 1e3:.4f}",
                        "—" if m.peak_effort is None else ", ".join(f"{v:.3g}" for v in m.peak_effort)])
    stem = "-".join(section.experiments[:1])
    if len(runs) > 1:
        roles = next(iter(runs.values())).roles
        if len({r.roles.robot for r in runs.values()}) == 1:      # joint errors compare on one robot only
            figure = plots.error_comparison({n: r.result for n, r in runs.items()}, roles,
                                            out / f"{stem}-comparison.png", section.comparison)
            lines += [f"![comparison]({figure.name})", ""]
        tcp = {n: (r.result.time, r.metrics.tcp_error) for n, r in runs.items() if r.metrics.tcp_error is not None}
        if tcp:
            tcp_figure = plots.tcp_error(tcp, out / f"{stem}-task-error.png")
            lines += [f"![task-point error]({tcp_figure.name})", ""]
    lines += diagnostics_lines(section, runs, out / f"{stem}-iterations.png", fmu_dir)
    if section.cross_check:
        lines += cross_check_lines(section, runs, out / f"{stem}-cross-check.png", fmu_dir)
    for name, run in runs.items():
        said = [f"What the FMUs said ([{name}/run.log]({name}/run.log)):", "", *[f"- {line}" for line in run.said],
                ""] if run.said else []
        if run.troubles:
            _say(summary_line(name, run.result, run.troubles))
        lines += [run.section.replace("### ", "### "), "", *said,
                  *[f"![{p.stem}]({name}/{p.name})" for p in run.figures], ""]
        system = load(name, fmu_dir=fmu_dir)
        if section.seed_table is not None:
            comparison = compare_with_seed(InProcessDiagram(system), run.roles, section.seed_table)
            lines += [f"#### {section.seed_table_title}", "",
                      comparison.markdown(), "",
                      f"{int(comparison.differs.sum())} of {comparison.differs.size} printed values differ "
                      "from this project's beyond the seed's last digit; why:", "",
                      *[f"- {note}" for note in section.seed_table_notes], ""]
        if section.bangbang:
            lines += ["#### The synchronized bang-bang", "",
                      bangbang_table(InProcessDiagram(system), run.roles, run.metrics.peak_effort,
                                     run.metrics.effort_units), ""]
        if section.seed_dynamics is not None:
            text = dynamics_table(run.roles.robot, section.seed_dynamics).text
            lines += ["#### Dynamics beside the seed's Lagrange derivation", "", text, ""]
    if section.tutorial is not None:
        lines += tutorial_lines(section, out)
    return lines, summary


def _parameter(system, instance: str, name: str):
    """A block parameter of an experiment: its value in the experiment, else its FMU's start value."""
    spec = next((b for b in system.blocks if b.name == instance), None)
    if spec is None:
        return None
    if name in spec.parameters:
        return spec.parameters[name]
    from fmpy import read_model_description

    from robofmu.system.plan import start_values

    return start_values(read_model_description(str(system.fmu_path(spec)), validate=False)).get(name)


def diagnostics_lines(section: ExperimentSection, runs: dict, path: Path, fmu_dir) -> list[str]:
    """The iterative solvers' diagnostics the runs recorded (``<instance>.iterations``,
    ``<instance>.residual``): a figure along the runs and a table; nothing if no run has any."""
    recorded = {name: plots.solver_diagnostics(run.result) for name, run in runs.items()}
    recorded = {name: found for name, found in recorded.items() if found}
    if not recorded:
        return []
    tolerances = {}
    rows = []
    for name, found in recorded.items():
        system = load(name, fmu_dir=fmu_dir)
        for instance, signals in found.items():
            tolerance = next((value for value in (_parameter(system, instance, name) for name in
                                                  ("tolerance", "position_tolerance")) if value is not None), None)
            if tolerance is not None:
                tolerances.setdefault(name, float(tolerance))
            it = signals.get("iterations")
            res = signals.get("residual")
            counts = ", ".join(f"{k}: {c}" for k, c in enumerate(np.bincount(it.astype(int))) if c) \
                if it is not None else "—"
            unit = printed(runs[name].result.units.get(f"{instance}.residual")
                           or runs[name].result.units.get(f"{instance}.position_residual"))
            unit = f" {unit}" if unit else ""
            rows.append([name, instance, "—" if it is None else f"{it[0]:.0f}",
                         "—" if it is None or len(it) < 2 else f"{it[1:].max():.0f}", counts,
                         "—" if res is None else f"{res.max():.2e}{unit}",
                         "—" if tolerance is None else f"{float(tolerance):g}{unit}"])
    title = section.diagnostics
    figure = plots.iterations({n: runs[n].result for n in recorded}, path, title, tolerances)
    return [f"### {title}", "", markdown_table(rows, [
        "experiment", "instance", "iterations at t = 0", "max iterations per step after t = 0",
        "communication points by iterations", "max residual", "tolerance"]), "",
        f"![iterations]({figure.name})", ""]


def cross_check_lines(section: ExperimentSection, runs: dict, path: Path, fmu_dir) -> list[str]:
    """The runs against their robot model's second, independent formulation of the dynamics
    (:mod:`robofmu.system.studies.crosscheck`), where the model has one: a figure and a table; nothing
    if no run's model has one."""
    from robofmu.system.studies.crosscheck import cross_check

    checks = {}
    for name, run in runs.items():
        found = cross_check(load(name, fmu_dir=fmu_dir), run.result, run.roles)
        if found is not None:
            _say(f"cross-check: {name} by the independent formulation ({found.method}, "
                 f"{found.step:g} s) in {found.seconds:.1f} s")
            checks[name] = found
    if not checks:
        return []
    title = section.cross_check_title
    figure = plots.constraint_residual(checks, path, title)
    rows = [[name, f"{c.method.upper() if c.method == 'rk4' else c.method}, {c.step:g} s",
             f"{c.residual.max():.2e} {printed(c.residual_units[0])}",
             f"{c.residual[-1]:.2e} {printed(c.residual_units[0])}",
             f"{c.residual_rate.max():.2e} {printed(c.residual_units[1])}",
             f"{c.joint_difference.max():.2e} {c.joint_unit}",
             f"{c.joint_difference[-1]:.2e} {c.joint_unit}", f"{c.seconds:.2f}"]
            for name, c in checks.items()]
    return [f"### {title}", "", section.cross_check_text, "", markdown_table(rows, [
        "experiment", "integrator, step", r"max \|Φ\|", r"\|Φ\| at the end", r"max \|Φ̇\|",
        r"max over joints \|q_indep − q_cosim\|", "at the end", "integration time (s)"]), "",
        f"![cross-check]({figure.name})", ""]


def tutorial_lines(section: ExperimentSection, out: Path) -> list[str]:
    """A worked-example study (:mod:`robofmu.system.studies.newton`) as report tables and a figure of
    the residual against the iteration."""
    from robofmu.system.studies import newton as newton_study

    path = section.tutorial
    _say(f"worked examples: {path.name}")
    examples = newton_study.run_study(path)
    tolerances = {float(e.spec.get("solver", {}).get("tolerance", math.nan)) for e in examples}
    tolerance = tolerances.pop() if len(tolerances) == 1 else None
    figure = plots.residual_history({e.spec.get("name", e.robot): [i.residual for i in e.iterates]
                                     for e in examples}, out / f"{path.stem}-residuals.png",
                                    section.tutorial_figure,
                                    tolerance if tolerance is not None and math.isfinite(tolerance) else None)
    title = section.tutorial_title
    return [f"### {title}", "", *newton_study.report(path, examples, level=4),
            f"![residual per iteration]({figure.name})", ""]


def workspace_section(entry: WorkspaceEntry, out: Path) -> list[str]:
    """A workspace study (:mod:`robofmu.system.studies.workspace`): its report as a section, its figures
    in ``out/<study>/``."""
    from robofmu.system.studies import workspace

    study = workspace.read_study(entry.study)
    _say(f"workspace study: {study.path.name}")
    result = workspace.run(study, progress=lambda line: _say("  " + line))
    folder = out / study.path.stem
    made = workspace.figures(result, folder)
    return workspace.report_lines(result, made, level=2, prefix=f"{folder.name}/")


def accuracy_section(plan: AccuracyStudy, out: Path, fmu_dir, quick: bool) -> list[str]:
    """Co-simulation error against the monolithic reference versus the communication step."""
    from robofmu.system.studies.convergence import study

    step_sizes = plan.quick_step_sizes if quick else plan.step_sizes
    lines = ["## Accuracy: co-simulation against a monolithic reference", "",
             f"The same diagram as one ODE (continuous controller, {defaults.REFERENCE_SOLVER} at rtol "
             f"{defaults.REFERENCE_RTOL:g}, integrated piecewise between the reference profile's discontinuities) "
             "against the co-simulation at its communication points. The effort is held over each step (zero-order hold, an effective "
             "delay of h/2), so the error is first order in h; Jacobi adds a step of delay through every "
             "direct-feedthrough block and a larger constant.", ""]
    for name in plan.experiments:
        _say(f"accuracy study: {name} against the monolithic reference")
        found = study(name, step_sizes, out / "convergence" / name, fmu_dir=fmu_dir,
                      progress=lambda line: _say("  " + line))
        lines += [f"### {name}", "", found.table, "", f"![convergence](convergence/{name}/convergence.png)", ""]
    return lines


def step_section(plan: StepResponses, out: Path, fmu_dir) -> list[str]:
    """Joint-reference steps through each robot's controller and plant FMUs against python-control."""
    from robofmu.system import stepresponse as sr

    _say("step responses: each robot's seed gains against python-control")
    lines = ["## Step responses", "",
             "A step on every joint's reference through the controller and plant FMUs (1 ms), from the "
             "robot's home configuration, against python-control: the continuous error dynamics, its ZOH "
             "discretization and the sampled-data loop (a ZOH-discretized double integrator closed by "
             "the sampled controller), which is what the FMUs implement. Metrics are taken relative to "
             "the initial value and time of the step.", ""]
    rows, figures = [], []
    for robot in plan.robots:
        for label, result in sr.demo_cases(robot, fmu_dir, out / "step"):
            cmp, figure = result
            m = cmp.metrics[next(iter(cmp.metrics))]
            rows.append([robot, label, f"{m.rise_time:.4f}", f"{m.settling_time:.4f}", f"{m.overshoot:.2f}",
                         f"{cmp.max_deviation('sampled'):.3f}", f"{cmp.max_deviation('zoh'):.3f}"])
            figures.append(f"![{robot} {label}](step/{figure.name})")
    design = plan.design
    if design is not None:
        gains = sr.design_gains(design.settling_time, design.overshoot)
        label = f"designed for {design.settling_time:g} s, {design.overshoot:g} %"
        for robot in design.robots:
            cmp = sr.compare(sr.cosimulate_step(fmu_dir, gains.kp, gains.kd, gains.ki, robot=robot))
            figure = sr.plot_comparison(cmp, out / "step", name=f"step_{robot}_designed")
            m = cmp.metrics[next(iter(cmp.metrics))]
            rows.append([robot, f"{label}: kp {gains.kp:.4g}, kd {gains.kd:.4g}, ki {gains.ki:.4g}",
                         f"{m.rise_time:.4f}", f"{m.settling_time:.4f}", f"{m.overshoot:.2f}",
                         f"{cmp.max_deviation('sampled'):.3f}", f"{cmp.max_deviation('zoh'):.3f}"])
            figures.append(f"![{robot} {label}](step/{figure.name})")
    lines += [markdown_table(rows, ["robot", "gains", "rise (s)", "settling (s)", "overshoot (%)",
                                    "max dev. from sampled-data model (% of amplitude)",
                                    "max dev. from c2d ZOH (% of amplitude)"]), "", *figures, ""]
    return lines


def robustness_section(study: RobustnessStudy, out: Path, fmu_dir, quick: bool = False) -> list[str]:
    """Robustness maps (``robofmu sweep``): the same grid for each labelled experiment, a heat map
    of the metric per experiment and the contours of the threshold compared."""
    from robofmu.system.sweep.design import Design, parse_axis
    from robofmu.system.sweep.figures import comparison_heatmaps, threshold_text
    from robofmu.system.sweep.run import run_sweep

    metric, threshold = study.metric, study.threshold
    vary = study.quick_vary if quick else study.vary
    lines = [f"## {study.title}", "", study.text, ""]
    runs = []
    for label, name in study.experiments.items():
        _say(f"robustness: {label} ({name}) over {'; '.join(vary)}")
        design = Design(name, [parse_axis(text) for text in vary])
        folder = out / "robustness" / label
        run = run_sweep(design, folder, fmu_dir=fmu_dir, metric=metric, threshold=threshold)
        runs.append((label, run))
    figure = comparison_heatmaps(runs, metric, threshold, out / "robustness-comparison.png")
    rows = []
    for label, run in runs:
        ok = [r for r in run.rows if r["status"] == "ok"]
        within = [r for r in ok if float(r[metric]) <= threshold]
        worst = max(ok, key=lambda r: float(r[metric])) if ok else None
        rows.append([label, run.design.experiment, f"{len(within)} of {len(run.rows)}",
                     "—" if worst is None else " ".join(f"{k} {float(worst[k]):g}" for k in run.design.names),
                     f"{len(run.rows)} runs in {run.seconds:.0f} s ({run.workers} workers)"])
    lines += [markdown_table(rows, ["controller", "experiment", f"runs within {threshold_text(runs[0][1], metric, threshold)}",
                                    "worst run", "sweep"]), "",
              f"![robustness]({figure.name})", "",
              *[f"- {label}: [report](robustness/{label}/report.md), [sweep.csv](robustness/{label}/sweep.csv)"
                for label, _ in runs], ""]
    return lines


def interop_section(plan: InteropSection, out: Path, fmu_dir) -> list[str]:
    """Each listed experiment in other FMI tools (a container of its FMUs, libcosim, ecos), the
    largest difference from the master's run in a table."""
    from robofmu.system.interop.compare import compare_tools

    lines = [f"## {plan.title}", "", plan.text, ""]
    rows, header = [], None
    for name in plan.experiments:
        _say(f"other FMI tools: {name}")
        runs = compare_tools(load(name, fmu_dir=fmu_dir), plan.stop_time, out / "interop")
        header = header or ["experiment", *[f"{r.tool} vs master {r.algorithm} "
                                            f"({'every output' if r.compared == 'every output' else 'q'})" for r in runs]]
        rows.append([name, *[r.note or ("0 (bit for bit)" if r.difference == 0 else f"{r.difference:.2g}")
                             for r in runs]])
    return [*lines, markdown_table(rows, header), "",
            "Largest absolute difference over the run (q: rad or m per joint; every output: in its own unit).", ""]


#: The line every demo report ends with; it marks a folder as an earlier demo's (replaceable).
SIGNATURE = "_Generated by `robofmu demo`"


def _only_runs(folder: Path) -> bool:
    """Whether ``folder`` holds nothing but ``robofmu run`` output folders (``results/<name>``)."""
    try:
        return folder.is_dir() and all(entry.is_dir() and all(owned_by("run", f) for f in entry.iterdir())
                                       for entry in folder.iterdir())
    except OSError:
        return False


def demo(out: Path, fmu_dir: str | Path = defaults.FMU_FOLDER, quick: bool = False) -> int:
    """Run the studies of ``system/studies/demo.toml`` and write ``out/report.md`` with its figures.

    The output folder is replaced whole, so no stale figure stays beside new results: the demo
    writes into a temporary sibling folder and swaps it in at the end (an interrupted or failed
    demo leaves ``out`` as it was). Before anything runs, ``out`` must be creatable, an earlier
    demo's folder (its report ends with :data:`SIGNATURE`) or a folder of ``robofmu run``
    outputs only, else UsageError (see :class:`~robofmu.system.usage.OutputFolder`).
    """
    start = time.perf_counter()
    plan = read_plan()
    final = Path(out)
    folder = OutputFolder(final, owned="demo", mark=None if _only_runs(final) else ("report.md", SIGNATURE))
    out = folder.open()
    try:
        body, summary = [], []
        for section in plan.sections:
            lines, rows = experiment_section(section, out, fmu_dir)
            body += lines
            summary += rows
        for entry in plan.workspace:
            body += workspace_section(entry, out)
        if plan.robustness is not None:
            body += robustness_section(plan.robustness, out, fmu_dir, quick)
        if plan.sampled_loop is not None:
            from robofmu.system.studies import sampled_loop

            body += sampled_loop.section(plan.sampled_loop, out, fmu_dir, say=_say)
        if plan.interop is not None:
            body += interop_section(plan.interop, out, fmu_dir)
        body += accuracy_section(plan.accuracy, out, fmu_dir, quick)
        body += step_section(plan.step_response, out, fmu_dir)
        table = markdown_table(summary, ["experiment (1 ms, Gauss-Seidel)", "max joint error",
                                         "max task-point error (mm)", "peak efforts (N·m or N, per joint)"])
        report = [f"# {plan.title}", "", plan.intro, "", "## Summary", "", table, "", *body,
                  f"{SIGNATURE} in {time.perf_counter() - start:.1f} s._"]
        (out / "report.md").write_text("\n".join(report) + "\n")
        figures = len(list(out.rglob("*.png")))
        folder.commit()
    except BaseException:
        folder.discard()
        raise
    print(table)
    _say(f"\nwrote {final / 'report.md'} and {figures} figures in {final} ({time.perf_counter() - start:.1f} s)")
    return 0
