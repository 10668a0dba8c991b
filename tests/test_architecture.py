"""The layout of ``robofmu.system`` as docs/design.md draws it, checked on the source.

- the co-simulation core sits flat in system/ (:data:`CORE`) beside the CLI entry; everything
  else is a wing, one subpackage each;
- the import graph (every import, lazy ones included) has no cycle;
- the core imports no wing; no command module imports another; no wing imports a command.
Each check is run on a made-up graph that breaks it, so none of them can pass vacuously.
"""
from __future__ import annotations

import ast
from pathlib import Path

import pytest

import robofmu.system

SYSTEM = Path(robofmu.system.__file__).resolve().parent

#: The co-simulation core: the only modules directly in system/ (with ``cli``, the entry).
CORE = {"analysis", "call_list", "compiled", "defaults", "diagram", "exchange", "experiment", "fmu", "interrupt", "master",
        "options", "plan", "plots", "result", "roles", "run", "units", "usage"}
ENTRY = "cli"
WINGS = {"commands", "interop", "packaging", "stepresponse", "studies", "sweep"}


def module_name(path: Path) -> str:
    parts = list(path.relative_to(SYSTEM).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(["robofmu.system", *parts])


def import_graph() -> dict[str, set[str]]:
    """Module -> the robofmu.system modules it imports anywhere in its text."""
    modules = {module_name(p): p for p in SYSTEM.rglob("*.py")}
    graph = {}
    for name, path in modules.items():
        found = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                for alias in node.names:
                    whole = f"{node.module}.{alias.name}"
                    found.add(whole if whole in modules else node.module)
            elif isinstance(node, ast.Import):
                found.update(alias.name for alias in node.names)
        graph[name] = {m for m in found if m in modules and m != name}
    return graph


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    state, found = {}, []

    def visit(node, stack):
        state[node] = "open"
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == "open":
                found.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = "done"

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    return found


def wing(module: str) -> str | None:
    """The wing of ``module`` (``interop``, …), None for the core, the entry and the package."""
    parts = module.split(".")
    return parts[2] if len(parts) > 2 and parts[2] in WINGS else None


def layering_problems(graph: dict[str, set[str]]) -> list[str]:
    problems = []
    for module, imported in graph.items():
        for other in imported:
            if wing(module) is None and module.split(".")[-1] in CORE and wing(other) is not None \
                    and other != "robofmu.system":
                problems.append(f"core {module} imports the wing module {other}")
            if wing(other) == "commands" and other != "robofmu.system.commands" and module.split(".")[-1] != ENTRY:
                problems.append(f"{module} imports the command module {other}")
    return sorted(problems)


def test_system_holds_only_the_core_the_entry_and_wings():
    modules = {p.stem for p in SYSTEM.glob("*.py")} - {"__init__"}
    assert modules == CORE | {ENTRY}, f"modules directly in system/ that are no core: {sorted(modules - CORE)}"
    packages = {p.parent.name for p in SYSTEM.glob("*/__init__.py")}
    assert packages == WINGS
    for name in WINGS:
        doc = ast.get_docstring(ast.parse((SYSTEM / name / "__init__.py").read_text()))
        assert doc and len(doc.split()) >= 25, f"system/{name}/__init__.py: a paragraph saying what lives there"


def test_the_import_graph_has_no_cycle():
    assert cycles(import_graph()) == []


def test_the_core_imports_no_wing_and_no_command_imports_another():
    assert layering_problems(import_graph()) == []


def test_the_checks_can_fail():
    made_up = {"robofmu.system.sweep.run": {"robofmu.system.sweep.report"},
               "robofmu.system.sweep.report": {"robofmu.system.sweep.run"},
               "robofmu.system.usage": {"robofmu.system.studies.replica"},
               "robofmu.system.commands.demo": {"robofmu.system.commands.run"},
               "robofmu.system.studies.demo": {"robofmu.system.commands.run"}}
    assert cycles(made_up) == [["robofmu.system.sweep.report", "robofmu.system.sweep.run",
                                "robofmu.system.sweep.report"]]
    assert layering_problems(made_up) == [
        "core robofmu.system.usage imports the wing module robofmu.system.studies.replica",
        "robofmu.system.commands.demo imports the command module robofmu.system.commands.run",
        "robofmu.system.studies.demo imports the command module robofmu.system.commands.run"]


@pytest.mark.parametrize("module", sorted(CORE))
def test_every_core_module_says_what_it_holds(module):
    doc = ast.get_docstring(ast.parse((SYSTEM / f"{module}.py").read_text()))
    assert doc, f"system/{module}.py has no module docstring"
