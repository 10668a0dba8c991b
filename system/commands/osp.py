"""``robofmu osp``: an experiment as libcosim's own configuration, block rates included."""
from __future__ import annotations

from pathlib import Path

from robofmu.system import options

HELP = "export an experiment for libcosim (OspSystemStructure.xml beside its FMUs), block rates included"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "osp", help=HELP,
        description="Write a folder holding OspSystemStructure.xml (the Open Simulation Platform's system "
                    "structure: libcosim, cosim-cli) beside copies of the experiment's FMUs: one simulator per "
                    "block with its sample time as its step size, the parameters as initial values, every wire "
                    "as scalar connections. A multi-rate experiment exports as it is (robofmu ssp and robofmu "
                    "container refuse it). libcosim runs it with its fixed-step algorithm, which is the master's "
                    "Jacobi loop (robofmu run --algorithm jacobi) at the same rates: a block's outputs reach the "
                    "others when its step ends. The folder is replaced whole, and only if robofmu wrote it.")
    p.add_argument("experiment", metavar="EXPERIMENT", help="experiment name or TOML file")
    options.add_out(p, "output folder (default: EXPERIMENT-osp)", metavar="DIR")
    options.add_fmus(p)
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    from robofmu.system.experiment import load
    from robofmu.system.interop.osp import MARK, OSP_FILE, export_osp
    from robofmu.system.usage import OutputFolder, check_fmu_folder, say, stopped

    option = "--out" if args.out else "the default output"
    folder = out = None
    try:
        system = load(args.experiment, fmu_dir=args.fmus)
        out = Path(args.out or f"{system.name}-osp")
        folder = OutputFolder(out, option, owned="osp", mark=(OSP_FILE, MARK))
        check_fmu_folder(system)
        export_osp(system, folder.open())
        written = folder.commit() / OSP_FILE
    except ValueError as exc:          # UsageError, ExperimentError, DiagramError
        return stopped("osp", exc)
    except OSError as exc:
        say("osp", f"{option} {out}: cannot write it: {exc.strerror or exc}")
        return 2
    finally:
        if folder is not None:
            folder.discard()
    print(written)
    return 0
