"""The misuse suite, files (issue 29 class 4): every FMU, SSP, container and CSV is written to a
temporary sibling ``.<name>.<random>.partial`` and renamed into place, so Ctrl-C leaves the
earlier file or none; ``--out`` never replaces a file that is not an output of the same kind;
an ``--out`` that cannot be written is a mistake in what was asked (exit status 2) for every
command, found before anything runs. Each refusal through :func:`misuse.assert_refused`.
"""
from __future__ import annotations

import os
import shutil
import zipfile
from pathlib import Path

import pytest
from pythonfmu import FmuBuilder

from misuse import PARTIAL, assert_refused
from robofmu.system.cli import main
from robofmu.system.interop.ssp import ssd_text

ROBOT = "rrp"
EXPERIMENT = "rrp-line"


def first_fmu() -> str:
    """The file of the robot's FMU built first."""
    from robofmu.components.robots import load_description

    return f"{load_description(ROBOT).fmu_blocks[0]}.fmu"


def unwritable(root: Path) -> Path:
    """A place no file can be created in, whoever runs the test: root may write where the
    permission bits say no, but nobody creates files in /proc."""
    if os.geteuid() != 0:
        locked = root / "locked"
        locked.mkdir(exist_ok=True)
        locked.chmod(0o555)
        return locked / "out"
    return Path("/proc/robofmu-misuse/out")


def listing(folder: Path) -> list[str]:
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


# -- Ctrl-C during robofmu build ---------------------------------------------------------------
def test_ctrl_c_while_the_builder_writes_leaves_the_earlier_fmu(capfd, tmp_path, fmu_root, monkeypatch):
    """pythonfmu writes half a zip, then Ctrl-C: --out keeps the earlier FMU byte for byte (the
    FMU is made in a temporary folder), and nothing else is left there."""
    out = tmp_path / "fmus"
    (out / ROBOT).mkdir(parents=True)
    earlier = out / ROBOT / first_fmu()
    shutil.copyfile(fmu_root / ROBOT / first_fmu(), earlier)
    before = listing(out)

    def interrupted(script, dest=".", **kwargs):
        Path(dest).parent.mkdir(parents=True, exist_ok=True)
        Path(dest).write_bytes(earlier.read_bytes()[:1000])        # a truncated zip
        raise KeyboardInterrupt

    monkeypatch.setattr(FmuBuilder, "build_FMU", staticmethod(interrupted))
    assert_refused(capfd, ["build", ROBOT, "--out", out], "interrupted", status=130, untouched=[earlier],
                   folders=[out])
    assert listing(out) == before
    with zipfile.ZipFile(earlier) as zf:
        assert zf.testzip() is None and "modelDescription.xml" in zf.namelist()


def test_ctrl_c_while_the_fmu_is_put_in_place_leaves_the_earlier_fmu(capfd, tmp_path, fmu_root, monkeypatch):
    """Ctrl-C in the middle of writing the FMU into --out (its temporary sibling half written):
    the earlier FMU stays, the sibling is deleted."""
    out = tmp_path / "fmus"
    (out / ROBOT).mkdir(parents=True)
    earlier = out / ROBOT / first_fmu()
    earlier.write_bytes(b"an earlier build")
    copy = shutil.copyfile
    seen = []

    def copy_interrupted(src, dst, *args, **kwargs):
        if str(dst).endswith(PARTIAL):
            seen.append(Path(dst))
            Path(dst).write_bytes(Path(src).read_bytes()[:1000])
            raise KeyboardInterrupt
        return copy(src, dst, *args, **kwargs)

    monkeypatch.setattr(shutil, "copyfile", copy_interrupted)
    assert_refused(capfd, ["build", ROBOT, "--out", out], "interrupted", status=130, untouched=[earlier],
                   folders=[out])
    assert len(seen) == 1 and seen[0].parent == out / ROBOT and seen[0].name.startswith(f".{first_fmu()}.")
    assert listing(out) == [ROBOT, f"{ROBOT}/{first_fmu()}"]


def test_ctrl_c_while_the_ssp_is_written_leaves_the_earlier_package(capfd, tmp_path, fmu_root, monkeypatch):
    """Ctrl-C while the block FMUs go into the package (its SSD already in): the earlier package
    stays, nothing half-written is left beside it."""
    out = tmp_path / "line.ssp"
    assert main(["ssp", EXPERIMENT, "--fmus", str(fmu_root), "--out", str(out)]) == 0
    assert "robofmu" in ssd_text(out)

    def interrupted(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(zipfile.ZipFile, "write", interrupted)
    assert_refused(capfd, ["ssp", EXPERIMENT, "--fmus", fmu_root, "--out", out], "interrupted", status=130,
                   untouched=[out], folders=[tmp_path])
    assert listing(tmp_path) == ["line.ssp"]


def test_ctrl_c_while_a_figure_is_written_leaves_the_earlier_figure(capfd, tmp_path, fmu_root, monkeypatch):
    """Every PNG goes through plots.save_figure (a temporary sibling renamed into place): Ctrl-C
    half-way through matplotlib's write leaves the earlier figure byte for byte, nothing beside it."""
    from matplotlib.figure import Figure

    out = tmp_path / "step"
    argv = ["step", "--robot", "rpp", "--stop-time", "0.05", "--fmus", str(fmu_root), "--out", str(out)]
    assert main(argv) == 0
    capfd.readouterr()
    (figure,) = out.glob("*.png")
    before = listing(out)

    def interrupted(self, fname, *args, **kwargs):
        Path(fname).write_bytes(b"\x89PNG half")
        raise KeyboardInterrupt

    monkeypatch.setattr(Figure, "savefig", interrupted)
    assert_refused(capfd, argv, "interrupted", status=130, untouched=[figure], folders=[out])
    assert listing(out) == before


# -- --out never replaces a file of another kind -------------------------------------------------
@pytest.mark.parametrize("command, name", [("ssp", "notes.txt"), ("container", "notes.txt"),
                                           ("ssp", "notes.ssp"), ("container", "notes.fmu")])
def test_out_refuses_a_file_that_is_not_its_output(capfd, tmp_path, fmu_root, command, name):
    notes = tmp_path / name
    notes.write_text("my notes, not an output of robofmu\n")
    assert_refused(capfd, [command, EXPERIMENT, "--fmus", fmu_root, "--out", notes], f"--out {notes}",
                   "it is not replaced", untouched=[notes], folders=[tmp_path])
    assert listing(tmp_path) == [name]


def test_out_refuses_an_output_of_the_other_kind(capfd, tmp_path, fmu_root):
    """An SSP package is not a container: ``robofmu container --out x.ssp`` leaves it."""
    package = tmp_path / "line.ssp"
    assert main(["ssp", EXPERIMENT, "--fmus", str(fmu_root), "--out", str(package)]) == 0
    assert_refused(capfd, ["container", EXPERIMENT, "--fmus", fmu_root, "--out", package], f"--out {package}",
                   "not a FMU container robofmu wrote", untouched=[package], folders=[tmp_path])


def test_out_replaces_its_own_earlier_output(capfd, tmp_path, fmu_root):
    """An earlier SSP and container robofmu wrote are replaced (the second export, with
    ``--inline`` / ``--expose-signals``, differs from the first), the package's mode kept."""
    from robofmu.system.interop.container import is_robofmu_container
    from robofmu.system.interop.ssp import is_robofmu_ssp

    package, container = tmp_path / "line.ssp", tmp_path / "line.fmu"
    assert main(["ssp", EXPERIMENT, "--fmus", str(fmu_root), "--out", str(package)]) == 0
    assert main(["container", EXPERIMENT, "--fmus", str(fmu_root), "--out", str(container)]) == 0
    assert '.ssv"' in ssd_text(package) and "ssv:ParameterSet" not in ssd_text(package)
    package.chmod(0o640)
    assert main(["ssp", EXPERIMENT, "--fmus", str(fmu_root), "--out", str(package), "--inline"]) == 0
    assert "ssv:ParameterSet" in ssd_text(package) and '.ssv"' not in ssd_text(package)
    assert package.stat().st_mode & 0o777 == 0o640
    first = container.read_bytes()
    assert main(["container", EXPERIMENT, "--fmus", str(fmu_root), "--out", str(container),
                 "--expose-signals"]) == 0
    assert container.read_bytes() != first and is_robofmu_container(container)
    assert is_robofmu_ssp(package) and not is_robofmu_container(package) and not is_robofmu_ssp(container)
    assert listing(tmp_path) == ["line.fmu", "line.ssp"]


# -- an unwritable --out: exit status 2, before anything runs ------------------------------------
UNWRITABLE = {
    "build": ["build", ROBOT, "--out", "{out}"],
    "ssp": ["ssp", EXPERIMENT, "--fmus", "{fmus}", "--out", "{out}.ssp"],
    "container": ["container", EXPERIMENT, "--fmus", "{fmus}", "--out", "{out}.fmu"],
    "sweep": ["sweep", EXPERIMENT, "--vary", "controller.kp=100,200", "--stop-time", "0.1", "--fmus", "{fmus}",
              "--out", "{out}"],
    "step": ["step", "--robot", ROBOT, "--stop-time", "0.1", "--fmus", "{fmus}", "--out", "{out}"],
}


#: The commands whose --out is a folder replaced whole (OutputFolder): they refused an unwritable
#: --out with status 2 before issue 29 already; here so that every command with --out is covered.
UNWRITABLE_FOLDERS = {
    "run": ["run", EXPERIMENT, "--fmus", "{fmus}", "--out", "{out}"],
    "workspace": ["workspace", "3rrp", "--out", "{out}"],
    "convergence": ["convergence", EXPERIMENT, "--fmus", "{fmus}", "--out", "{out}"],
    "demo": ["demo", "--quick", "--out", "{out}"],
}


@pytest.mark.parametrize("case", [*UNWRITABLE, *UNWRITABLE_FOLDERS])
def test_an_unwritable_out_is_refused_with_status_2(capfd, tmp_path, fmu_root, case):
    out = unwritable(tmp_path)
    argv = [str(a).format(out=out, fmus=fmu_root) for a in {**UNWRITABLE, **UNWRITABLE_FOLDERS}[case]]
    given = argv[argv.index("--out") + 1]
    assert_refused(capfd, argv, f"--out {given}", folders=[tmp_path])
