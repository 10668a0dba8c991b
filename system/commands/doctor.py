"""``robofmu doctor``: what a process needs to run the FMUs, and whether it works here."""
from __future__ import annotations

from pathlib import Path

from robofmu.system import options

HELP = "what a process needs to run the FMUs, and whether it works here"


def add_parser(subparsers):
    p = subparsers.add_parser(
        "doctor", help=HELP,
        description="Tell what an importing process needs to run the FMUs: the Python interpreter they were "
                    "built for (path, version), the libpython a non-Python host (e.g. libcosim's cosim) must "
                    "preload, the venv's bin to put on PATH, and the packages the FMUs import (from robofmu's "
                    "requirements); print the exact `export` lines. Then check: each package importable (with "
                    "its version), every described robot's FMUs present under --fmus and built from these "
                    "robofmu sources (their vendor annotation's source hash), one FMU instantiated and stepped "
                    "through fmpy in a fresh process. Exit status 0 when everything checks, 1 otherwise (one "
                    "line per problem).")
    options.add_fmus(p)
    p.set_defaults(func=main)
    return p


def main(args) -> int:
    from robofmu.system.packaging.doctor import doctor

    return doctor(Path(args.fmus))
