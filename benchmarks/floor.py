"""The C++ floor of ``make bench``: the chess-pd co-simulation loop written in C++ directly on
Pinocchio's C++ API (``benchmarks/floor/loop.cpp``), timed, and its trajectory compared with
robofmu's.

    .venv/bin/python benchmarks/floor.py [--experiment chess-pd] [--fmus fmus] [--repeat 5]

The program reads the loop's numbers (:func:`loop_spec.spec`) at run time from a small text file
written here, runs the loop ``repeats`` times in one process (state reset between repeats; only
the stepping loop timed, std::chrono::steady_clock) and writes the last repeat's record.

Build: the compiler (``$CXX``, else ``g++``) with CMake's Release flags (``-O3 -DNDEBUG``,
``-std=c++17``), the compile definitions the installed Pinocchio exports to its users (read from
its CMake package: ``pinocchio_parsers`` and what it links), Pinocchio's headers and libraries
from the ``pin`` wheel's cmeel prefix (rpath to its ``lib``), Eigen and urdfdom's headers (not
in those wheels) from the ``cmeel-eigen`` / ``cmeel-urdfdom-headers`` wheels, downloaded by pip
into ``benchmarks/floor/build/deps/`` once. The binary is cached under ``benchmarks/floor/build/``
by a hash of the source and the whole compile command. Without a compiler, the prefix or the
headers, :func:`run_floor` returns a one-line note instead.
"""
from __future__ import annotations

import argparse
import hashlib
import importlib.util
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
SOURCE = HERE / "floor" / "loop.cpp"
BUILD = HERE / "floor" / "build"
FLAGS = ["-O3", "-DNDEBUG", "-std=c++17"]
#: Eigen's version the cmeel wheels of Pinocchio and eigenpy are built against (eigenpy's
#: ``build`` extra asks for cmeel-eigen >= 3.4.1, the newest 3.4 release).
EIGEN = "cmeel-eigen==3.4.1"
#: The target whose users' compile definitions the program needs (it links these libraries).
TARGETS = ("pinocchio::pinocchio_parsers", "pinocchio::pinocchio_default")
LIBRARIES = ("pinocchio_parsers", "pinocchio_default")
#: The columns compared with robofmu (its names).
COMPARED = ("plant.q", "plant.qd", "controller.tau", "ik.q_ref")


class Skip(Exception):
    """The floor cannot be built here (the message says why, on one line)."""


# -- the toolchain ---------------------------------------------------------------------------------
def _prefix() -> Path:
    """The cmeel prefix holding Pinocchio's headers and libraries (found from Python)."""
    candidates = []
    spec = importlib.util.find_spec("pinocchio")
    if spec is not None and spec.origin:
        candidates += [p for p in Path(spec.origin).resolve().parents if p.name == "cmeel.prefix"]
    candidates += [Path(p) / "cmeel.prefix" for p in sys.path if p]
    for prefix in candidates:
        if (prefix / "include" / "pinocchio" / "config.hpp").is_file() and \
                (prefix / "lib" / "libpinocchio_default.so").exists():
            return prefix
    raise Skip("no Pinocchio C++ headers and libraries (the pin wheel's cmeel prefix) found")


def _cmake_targets(prefix: Path) -> dict[str, dict[str, str]]:
    """The INTERFACE_* properties of every imported target in the prefix's CMake packages."""
    targets: dict[str, dict[str, str]] = {}
    for path in sorted((prefix / "lib" / "cmake").glob("*/*Targets.cmake")):
        text = path.read_text(errors="replace")
        for match in re.finditer(r"set_target_properties\((\S+) PROPERTIES\n(.*?)\n\)", text, re.S):
            props = dict(re.findall(r'^\s*(INTERFACE_\w+) "([^"]*)"', match.group(2), re.M))
            targets.setdefault(match.group(1), {}).update(props)
    return targets


def _definitions(prefix: Path) -> tuple[list[str], dict[str, str]]:
    """``-D`` flags a user of :data:`TARGETS` compiles with (transitively, as CMake would give
    them), and the definitions by name."""
    targets = _cmake_targets(prefix)
    if TARGETS[0] not in targets:
        raise Skip(f"no CMake package for {TARGETS[0]} under {prefix / 'lib' / 'cmake'}")
    found: list[str] = []
    seen: set[str] = set()

    def visit(name: str) -> None:
        if name in seen or name not in targets:
            return
        seen.add(name)
        props = targets[name]
        for item in props.get("INTERFACE_COMPILE_DEFINITIONS", "").replace("\\$", "$").split(";"):
            ref = re.fullmatch(r"\$<TARGET_PROPERTY:([^,>]+),INTERFACE_COMPILE_DEFINITIONS>", item)
            if ref:
                visit(ref.group(1))
            elif item and "$<" not in item and item not in found:
                found.append(item)
        for link in props.get("INTERFACE_LINK_LIBRARIES", "").split(";"):
            visit(link)

    for name in TARGETS:
        visit(name)
    values = dict(d.split("=", 1) if "=" in d else (d, "") for d in found)
    return [f"-D{d}" for d in found], values


def _wheel_headers(requirement: str, marker: str) -> Path:
    """The include folder of a header-only cmeel wheel: its ``cmeel.prefix/include/<marker>``
    parent, downloaded by pip into ``build/deps/`` the first time."""
    name = re.split(r"[=<>~! ]", requirement, 1)[0]
    root = BUILD / "deps" / re.sub(r"[^A-Za-z0-9.=_-]", "_", requirement)
    include = root / "cmeel.prefix" / "include"
    stamp = root / ".complete"
    if not stamp.is_file():
        shutil.rmtree(root, ignore_errors=True)
        BUILD.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=BUILD) as tmp:
            try:
                run = subprocess.run(
                    [sys.executable, "-m", "pip", "download", "--no-deps", "--only-binary", ":all:",
                     "--disable-pip-version-check", "-q", "-d", tmp, requirement],
                    capture_output=True, text=True, timeout=600)
            except (OSError, subprocess.TimeoutExpired) as exc:
                raise Skip(f"cannot download {requirement} ({exc.__class__.__name__})") from None
            wheels = list(Path(tmp).glob("*.whl"))
            if run.returncode or not wheels:
                last = (run.stderr.strip().splitlines() or ["no wheel"])[-1]
                raise Skip(f"cannot download {requirement}: {last}")
            with zipfile.ZipFile(wheels[0]) as archive:
                members = [m for m in archive.namelist() if m.startswith("cmeel.prefix/include/")]
                archive.extractall(root, members)
        stamp.write_text(f"{requirement}\n{wheels[0].name}\n")
    hits = sorted(include.glob(f"**/{marker}"))
    if not hits:
        raise Skip(f"the {name} wheel holds no {marker}")
    return hits[0].parents[len(Path(marker).parts) - 1]


def _include_dirs(prefix: Path, defines: dict[str, str]) -> list[Path]:
    """Eigen's and urdfdom's headers (the prefix's own if present, else the wheels'), then the
    prefix's."""
    dirs = []
    local = prefix / "include" / "eigen3"
    dirs.append(local if (local / "Eigen" / "Core").is_file() else _wheel_headers(EIGEN, "Eigen/Core"))
    if "PINOCCHIO_WITH_URDFDOM" in defines:
        local = [d for d in (prefix / "include", prefix / "include" / "urdfdom_headers")
                 if (d / "urdf_model" / "model.h").is_file()]
        if local:
            dirs.append(local[0])
        else:
            version = ".".join(defines.get(f"PINOCCHIO_URDFDOM_HEADERS_{k}_VERSION", "")
                               for k in ("MAJOR", "MINOR", "PATCH"))
            pin = f"=={version}" if re.fullmatch(r"\d+\.\d+\.\d+", version) else ""
            dirs.append(_wheel_headers(f"cmeel-urdfdom-headers{pin}", "urdf_model/model.h"))
        dirs.append(prefix / "include" / "urdfdom")
    dirs.append(prefix / "include")
    return dirs


def _compiler() -> tuple[str, str]:
    """Path and version line of the C++ compiler."""
    name = os.environ.get("CXX", "g++")
    path = shutil.which(name)
    if path is None:
        raise Skip(f"no C++ compiler ({name}) on PATH")
    try:
        version = subprocess.run([path, "--version"], capture_output=True, text=True,
                                 timeout=60).stdout.splitlines()[0].strip()
    except (OSError, IndexError, subprocess.TimeoutExpired):
        raise Skip(f"the C++ compiler {path} does not run") from None
    return path, version


def build() -> dict:
    """The compiled loop (cached by a hash of the source and the compile command).

    Returns ``{"binary", "compiler", "flags", "command"}``; raises :class:`Skip` where it cannot
    be built, RuntimeError if the compiler refuses the source.
    """
    cxx, version = _compiler()
    prefix = _prefix()
    defines, values = _definitions(prefix)
    includes = _include_dirs(prefix, values)
    lib = prefix / "lib"
    flags = FLAGS + defines
    command = [cxx, *flags, *[f"-isystem{d}" for d in includes], str(SOURCE), "-o", "OUT",
               f"-L{lib}", f"-Wl,-rpath,{lib}", *[f"-l{name}" for name in LIBRARIES]]
    key = hashlib.sha256(SOURCE.read_bytes() + "\0".join([version, *command]).encode()).hexdigest()[:16]
    binary = BUILD / f"loop-{key}"
    command[command.index("OUT")] = str(binary)
    info = {"binary": binary, "compiler": version, "flags": " ".join(flags), "command": command}
    if binary.is_file() and os.access(binary, os.X_OK):
        return info
    BUILD.mkdir(parents=True, exist_ok=True)
    partial = binary.with_name(binary.name + f".{os.getpid()}.tmp")
    command[command.index(str(binary))] = str(partial)
    log = BUILD / "compile.log"
    try:
        run = subprocess.run(command, capture_output=True, text=True)
    finally:
        command[command.index(str(partial))] = str(binary)
    log.write_text(" ".join(command) + "\n\n" + run.stdout + run.stderr)
    if run.returncode:
        partial.unlink(missing_ok=True)
        raise RuntimeError(f"compiling {SOURCE.name} failed (exit {run.returncode}); see {log}")
    partial.replace(binary)
    return info


# -- the run ------------------------------------------------------------------------------------------
def _number(value) -> str:
    """Integers as such, floats by repr (round-trips exactly; inf as "inf", which strtod reads)."""
    if isinstance(value, (int, np.integer)) and not isinstance(value, bool):
        return str(int(value))
    return repr(float(value))


def _input_text(spec: dict, repeats: int) -> str:
    """The loop's numbers for loop.cpp: one ``key values...`` per line (``str:key text``)."""
    tr, ik, ctl, plant, payload = (spec[k] for k in ("trajectory", "ik", "controller", "plant", "payload"))
    waypoints = np.asarray(tr["waypoints"], dtype=float)
    axis_tolerance = ik.get("axis_tolerance")
    if axis_tolerance is None:
        from robofmu.components.ik.closed_form import AXIS_TOLERANCE as axis_tolerance
    rows = {
        "h": [spec["h"]], "n_steps": [spec["n_steps"]], "repeats": [repeats],
        "gravity": spec["gravity"],
        "task_dim": [waypoints.shape[1]],
        "task_axes": spec.get("task_axes", list(range(waypoints.shape[1]))),
        "waypoints": waypoints.ravel(), "durations": tr["durations"], "pause": [tr["pause"]],
        "cruise_factor": [tr["cruise_factor"]], "breakpoints": tr["breakpoints"],
        "snap_tolerance": [tr["snap_tolerance"]], "grip_close": [tr["grip_close"]],
        "grip_open": [tr["grip_open"]],
        **{k: [ik[k]] for k in ("a1", "a2", "a3", "a4", "tool_pitch", "elbow_sign")},
        "qd_limit": ik["qd_limit"], "axis_tolerance": [axis_tolerance],
        "kp": [ctl["kp"]], "kd": [ctl["kd"]], "ki": [ctl["ki"]],
        "controller_payload_mass": [ctl["payload_mass"]],
        "q0": plant["q0"], "qd0": plant["qd0"], "plant_payload_mass": [plant["payload_mass"]],
        "max_substep": [plant["max_substep"]],
        "payload_joint": [payload["joint"]], "payload_lever": payload["lever"],
    }
    lines = [f"str:urdf {spec['urdf']}", f"str:tcp_frame {spec['tcp_frame']}"]
    lines += [f"{key} " + " ".join(_number(v) for v in values) for key, values in rows.items()]
    return "\n".join(lines) + "\n"


def run_floor(spec: dict, out_npz: Path, repeats: int = 5) -> dict | str:
    """Build (once) and run the C++ floor on the loop ``spec`` (:func:`loop_spec.spec`).

    Writes ``out_npz`` (``time`` (N+1,), ``data`` (N+1, m), ``columns`` in robofmu's names) and
    returns ``{"loop": best loop time (s), "n_steps", "compiler", "flags", "loops": every
    repeat's (s), "command": the compile command}``; or a one-line note why it was skipped.
    """
    try:
        info = build()
    except Skip as exc:
        return f"C++ floor skipped: {exc}"
    with tempfile.TemporaryDirectory(prefix="floor-") as tmp:
        source, raw = Path(tmp) / "loop.in", Path(tmp) / "record.f64"
        source.write_text(_input_text(spec, repeats))
        run = subprocess.run([str(info["binary"]), str(source), str(raw)], capture_output=True, text=True)
        if run.returncode:
            raise RuntimeError(f"C++ floor failed (exit {run.returncode}): {run.stderr.strip()}")
        report = json.loads(run.stdout)
        n = int(report["n_steps"])
        data = np.fromfile(raw, dtype=np.float64).reshape(n + 1, int(report["width"]))
    time = spec["h"] * np.arange(n + 1)
    out_npz = Path(out_npz)
    out_npz.parent.mkdir(parents=True, exist_ok=True)
    np.savez(out_npz, time=time, data=data, columns=np.array(report["columns"]))
    return {"loop": min(report["loops"]), "n_steps": n, "compiler": info["compiler"],
            "flags": info["flags"], "loops": report["loops"], "unreachable": report["unreachable"],
            "command": " ".join(info["command"])}


# -- the comparison with robofmu ---------------------------------------------------------------------
def compare(floor: dict, columns: list[str], data: np.ndarray) -> dict[str, float]:
    """max |floor - robofmu| per compared signal (every component), over every row."""
    mine = {str(c): k for k, c in enumerate(floor["columns"])}
    theirs = {c: k for k, c in enumerate(columns)}
    out = {}
    for base in COMPARED:
        names = [c for c in mine if c.startswith(base + "[")]
        out[base] = float(max(np.max(np.abs(floor["data"][:, mine[c]] - data[:, theirs[c]])) for c in names))
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiment", default="chess-pd")
    parser.add_argument("--fmus", default="fmus")
    parser.add_argument("--repeat", type=int, default=5, help="loop repeats inside the C++ process")
    args = parser.parse_args(argv)
    sys.path.insert(0, str(HERE))
    from loop_spec import spec as loop_spec
    from robofmu.system.experiment import load
    from robofmu.system.studies.replica import InProcessDiagram

    spec = loop_spec(args.experiment, args.fmus)
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "floor.npz"
        floor = run_floor(spec, out, args.repeat)
        if isinstance(floor, str):
            print(floor)
            return 0
        with np.load(out) as f:
            record = {"columns": f["columns"], "data": f["data"], "time": f["time"]}
    system = load(args.experiment, fmu_dir=args.fmus)
    result = InProcessDiagram(system).sampled(spec["h"], spec["stop"])
    if not np.array_equal(result.time, record["time"]):
        raise SystemExit("the C++ floor's time grid differs from robofmu's")
    diff = compare(record, list(result.columns), result.data)
    n = floor["n_steps"]
    python = result.info["wall_time"]
    print(f"{args.experiment}: {n} steps of {spec['h']:g} s; {floor['compiler']}")
    print(f"  {'runner':<24}{'loop (s)':>10}{'per step (us)':>15}")
    print(f"  {'C++ floor (best of ' + str(len(floor['loops'])) + ')':<24}{floor['loop']:>10.4f}"
          f"{floor['loop'] / n * 1e6:>15.3f}")
    print(f"  {'in-process Python':<24}{python:>10.4f}{python / n * 1e6:>15.3f}")
    print(f"  ratio Python / C++: {python / floor['loop']:.1f}")
    print("  max |C++ - robofmu in-process|: " + ", ".join(f"{k} {v:.3g}" for k, v in diff.items()))
    return 0


if __name__ == "__main__":
    sys.exit(main())
