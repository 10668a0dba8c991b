"""Benchmark: robofmu against its peers on the same loop — the C++ floor (Pinocchio's C++ API),
pydrake and bdsim + Robotics Toolbox — each timed beside robofmu's master in one run, each one's
joint trajectory compared with robofmu's.

Every runner is a fresh process; the runners take turns round after round (``--rounds``, best
kept), so a machine's load falls on all of them alike. The peers run in their own environments
under ``benchmarks/peers/`` (``make bench-peers`` makes them: they are not project
dependencies) and read the loop's numbers from :mod:`loop_spec`, never robofmu itself:

- ``pydrake``: MultibodyPlant and LeafSystems (``benchmarks/peers/drake_loop.py``), each of its
  integrator variants;
- ``bdsim + RTB``: a bdsim block diagram on Robotics Toolbox dynamics
  (``benchmarks/peers/bdsim_loop.py``), each of its variants;
- ``C++ floor``: the same loop compiled on Pinocchio's C++ API (``benchmarks/floor.py``),
  skipped with a note where no compiler or headers are found.

A peer whose environment is missing is skipped with the command that makes it.

    make bench-peers     # or: .venv/bin/python benchmarks/peers.py [--rounds 3] [--experiment chess-pd]
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
import loop as loop_bench            # noqa: E402  (benchmarks/loop.py: run_child, max_diff)
from loop_spec import spec as loop_spec   # noqa: E402

#: Variants left out of the rounds, and why (each can be run alone with the peer's --variant).
UNTIMED = {"bdsim + RTB": {"urdf-rk4": "RTB's pure-Python dynamics on the URDF robot, ~40 ms a step "
                                       "(10-17 min a run); the mdh variants run the same robot on RTB's C code"}}

#: A peer's variant follows robofmu's trajectory when its joints stay this close (rad) to it.
SAME_TRAJECTORY = 1e-5

PEERS = {   # name: (environment, script)
    "pydrake": (HERE / "peers" / ".venv-drake", HERE / "peers" / "drake_loop.py"),
    "bdsim + RTB": (HERE / "peers" / ".venv-bdsim", HERE / "peers" / "bdsim_loop.py"),
}


def run_peer(name: str, spec_path: Path, out: Path, variant: str | None) -> dict:
    environment, script = PEERS[name]
    cmd = [str(environment / "bin" / "python"), str(script), str(spec_path), str(out)]
    if variant:
        cmd += ["--variant", variant]
    proc = subprocess.run(cmd, capture_output=True, text=True, cwd=HERE.parent)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"{name} {variant or ''}: failed ({proc.returncode})\n{proc.stdout[-2000:]}\n"
                           f"{proc.stderr[-2000:]}")
    return json.loads(lines[-1][len("RESULT "):])


def variants(name: str) -> list[str]:
    environment, script = PEERS[name]
    proc = subprocess.run([str(environment / "bin" / "python"), str(script), "--list-variants"],
                          capture_output=True, text=True, cwd=HERE.parent)
    if proc.returncode != 0:
        raise RuntimeError(f"{name}: --list-variants failed\n{proc.stderr[-2000:]}")
    return [line.split()[0] for line in proc.stdout.splitlines() if line.strip()]


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--experiment", default="chess-pd")
    parser.add_argument("--fmus", default="fmus")
    parser.add_argument("--rounds", type=int, default=3, help="rounds of every runner; best kept")
    args = parser.parse_args(argv)
    fmu_root = Path(args.fmus).resolve()
    numbers = loop_spec(args.experiment, fmu_root)
    h, stop = numbers["h"], numbers["stop"]
    notes, runners = [], []             # runners: (label, callable(out) -> info)
    with tempfile.TemporaryDirectory(prefix="robofmu-peers-") as tmp:
        tmp = Path(tmp)
        spec_path = tmp / "spec.json"
        spec_path.write_text(json.dumps(numbers))
        runners.append(("robofmu master", lambda out: loop_bench.run_child(
            args.experiment, "robofmu", h, stop, fmu_root, tmp / "unused.ssp", out)))
        runners.append(("robofmu in-process", lambda out: loop_bench.run_child(
            args.experiment, "in-process", h, stop, fmu_root, tmp / "unused.ssp", out)))
        try:
            import floor
            probe = floor.run_floor(numbers, tmp / "floor-probe.npz", repeats=1)
        except Exception as exc:            # noqa: BLE001  (a note, not a failed benchmark)
            probe = f"C++ floor failed: {type(exc).__name__}: {exc}"
        if isinstance(probe, str):
            notes.append(probe)
        else:
            runners.append(("C++ floor", lambda out: floor.run_floor(numbers, out)))
        for name, (environment, script) in PEERS.items():
            if not (environment / "bin" / "python").is_file():
                notes.append(f"{name} skipped: no environment {environment.relative_to(HERE.parent)} "
                             "(make bench-peers creates it)")
                continue
            for variant in variants(name):
                if variant in UNTIMED.get(name, {}):
                    notes.append(f"{name} ({variant}) not timed: {UNTIMED[name][variant]}")
                    continue
                runners.append((f"{name} ({variant})",
                                lambda out, name=name, variant=variant: run_peer(name, spec_path, out, variant)))
        best: dict[str, dict] = {}
        for round_ in range(args.rounds):
            for label, run in runners:
                out = tmp / f"{label.replace(' ', '_').replace('/', '_')}-{round_}.npz"
                try:
                    info = run(out)
                except RuntimeError as exc:
                    notes.append(f"{label}: {str(exc).splitlines()[0]}")
                    continue
                per = info["loop"] / info["n_steps"]
                if label not in best or per < best[label]["per"]:
                    best[label] = {**info, "per": per, "npz": out}
            print(f"round {round_ + 1}/{args.rounds} done", file=sys.stderr, flush=True)
        if "robofmu master" not in best:
            print("robofmu's master did not run: " + "; ".join(notes), file=sys.stderr)
            return 1
        master = best["robofmu master"]
        print(f"{args.experiment}, {stop:g} s at h = {h * 1e3:g} ms ({numbers['n_steps']} steps); "
              f"each runner a fresh process, best of {args.rounds} interleaved rounds\n")
        print("| runner | integration order | per step (µs) | its time / master's | max abs(q - q robofmu) (rad) |")
        print("|---|---|---|---|---|")
        for label, info in sorted(best.items(), key=lambda item: item[1]["per"]):
            info["diff"], _ = loop_bench.max_diff(info["npz"], master["npz"], "plant.q[")
            version = f" {info['version']}" if info.get("version") else ""
            order = info.get("order", 4 if label.startswith(("robofmu", "C++")) else "?")
            print(f"| {label}{version} | {order} | {info['per'] * 1e6:.1f} | {info['per'] / master['per']:.2f} | "
                  f"{'—' if label == 'robofmu master' else format(info['diff'], '.2g')} |")
        print()
        floor_info = best.get("C++ floor")
        if floor_info:
            print(f"master / C++ floor: {master['per'] / floor_info['per']:.1f}x (goal <= 20x); "
                  f"in-process / C++ floor: {best['robofmu in-process']['per'] / floor_info['per']:.1f}x (goal <= 12x)")
        for name in PEERS:
            mine = [info for label, info in best.items() if label.startswith(name)]
            close = [info for info in mine if info["diff"] <= SAME_TRAJECTORY]
            for what, among in (("fastest variant", mine), (f"fastest variant within {SAME_TRAJECTORY:g} rad of "
                                                            "robofmu's trajectory", close)):
                if among:
                    fastest = min(among, key=lambda info: info["per"])
                    verdict = "faster" if master["per"] < fastest["per"] else "NOT faster"
                    print(f"master vs {name}'s {what} ({fastest.get('variant', '?')}): {verdict} "
                          f"({master['per'] * 1e6:.0f} vs {fastest['per'] * 1e6:.0f} µs per step)")
        for note in notes:
            print(note)
    return 0


if __name__ == "__main__":
    sys.exit(main())
