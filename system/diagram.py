"""A block diagram: blocks (FMU file, instance name, parameters) and the wires between them.

Wires name variables by instance and variable; a vector base wires every index at once:
``"ik.q_ref -> controller.q_ref"`` connects ``q_ref[1]`` .. ``q_ref[n]``. A diagram is built in
Python or read from a declarative experiment file (TOML) under ``system/experiments/``.
"""
from __future__ import annotations

import fnmatch
import re
from dataclasses import dataclass, field
from pathlib import Path

from robofmu.components.parameters import INTEGER_RANGE
from robofmu.system import defaults

_INDEXED = re.compile(r"^(.*)\[(\d+(?:,\d+)*)\]$")       # q[2]; a matrix entry J[1,2]
_PARAMETER = re.compile(r"^([A-Za-z_][\w-]*)\.([A-Za-z_][\w\[\],]*)$")    # controller.kp, plant.q0[2]
_WIRE = re.compile(r"^\s*([A-Za-z_]\w*)\.([\w\[\]]+)\s*->\s*([A-Za-z_]\w*)\.([\w\[\]]+)\s*$")


def parameter_address(name: str) -> tuple[str, str]:
    """``BLOCK.PARAM`` (``controller.kp``, ``plant.q0[2]``) as ``(block, parameter)``: the one
    grammar of a block parameter's address (experiment files, ``--set``, a sweep's ``--vary``).

    Raises
    ------
    ValueError
        ``'<name>' is not BLOCK.PARAM (e.g. controller.kp)``.
    """
    match = _PARAMETER.match(name.strip())
    if match is None:
        raise ValueError(f"{name!r} is not BLOCK.PARAM (e.g. controller.kp)")
    return match.group(1), match.group(2)


def expand(names, base: str) -> list[str]:
    """The variables ``base`` names among ``names``: itself if it is one, else ``base[1]``,
    ``base[2]``, ... in index order (FMI structured naming; a matrix ``base[1,1]``,
    ``base[1,2]``, ... row-major); [] if none."""
    names = list(names)
    if base in names:
        return [base]
    found = sorted((tuple(int(i) for i in m.group(2).split(",")), n)
                   for n in names if (m := _INDEXED.match(n)) and m.group(1) == base)
    return [n for _, n in found]


def bases(names) -> list[str]:
    """The vector bases and scalar names among ``names`` (``q[1]``, ``q[2]``, ``kp`` -> ``q``,
    ``kp``), each once, in order of first appearance."""
    return list(dict.fromkeys(m.group(1) if (m := _INDEXED.match(n)) else n for n in names))


def matching(columns: list[str], entry: str) -> list[int]:
    """Indices of the ``columns`` (``instance.variable``) one record entry names.

    Parameters
    ----------
    columns : list of str
    entry : str
        An exact column (``plant.q[2]``), a vector base (``plant.q``: ``plant.q[1]`` ..
        ``plant.q[n]``) or an fnmatch pattern (``plant.*``, ``*.tau[[]*``); tried in that order,
        so an exact name with brackets is not read as a pattern's character class.

    Returns
    -------
    list of int
        In column order; [] if the entry names nothing.
    """
    index = {column: k for k, column in enumerate(columns)}
    if entry in index:
        return [index[entry]]
    members = expand(columns, entry)
    if members:
        return sorted(index[m] for m in members)
    return [k for k, c in enumerate(columns) if fnmatch.fnmatchcase(c, entry)]


def select(columns: list[str], patterns: list[str] | None) -> list[int]:
    """Indices of the ``columns`` (``instance.variable``) any entry names (:func:`matching`:
    exact names, vector bases, fnmatch patterns), in column order; all if None."""
    if patterns is None:
        return list(range(len(columns)))
    if isinstance(patterns, str):
        patterns = [patterns]
    chosen = {k for entry in patterns for k in matching(columns, entry)}
    return sorted(chosen)


def unmatched(columns: list[str], patterns: list[str] | None) -> list[str]:
    """The entries of ``patterns`` that name none of the ``columns`` ([] for None)."""
    if patterns is None:
        return []
    if isinstance(patterns, str):
        patterns = [patterns]
    return [entry for entry in patterns if not matching(columns, entry)]


def spread(names: list[str], value, what: str) -> list:
    """One value per name: a sequence of ``len(names)`` values, or one scalar for one name."""
    values = list(value) if isinstance(value, (list, tuple)) or hasattr(value, "__array__") else [value]
    if len(values) != len(names):
        raise ValueError(f"{what} has {len(names)} element{'s' * (len(names) != 1)}, got {len(values)} "
                         f"value{'s' * (len(values) != 1)}")
    return values


def coerce(kind: str, value, what: str):
    """``value`` as the Python value of an FMI ``kind``: the one parser of typed FMI values.

    Used for experiment parameters, model-description start values, SSV parameter values and
    libcosim initial values alike.

    Parameters
    ----------
    kind : {"Real", "Integer", "Enumeration", "Boolean", "String"}
        The FMI type of the variable.
    value : float, int, bool, str
        A Python value, or a string as a model description's ``start`` attribute (or an SSV
        ``value``) spells it: ``"0.5"``, ``"3"``, ``"true"`` / ``"false"`` / ``"1"`` / ``"0"``.
    what : str
        The variable, for the error message.

    Returns
    -------
    float, int, bool or str
        float for Real, int for Integer and Enumeration, bool for Boolean, str for String.

    Raises
    ------
    ValueError
        Naming ``what``, if ``value`` is not a ``kind`` (a bool is no Real, 1.5 no Integer, 2
        no Boolean, a number no String), an Integer is beyond 32 bits (FMI's fmi2Integer: fmpy's
        ctypes would pass 2**32 + 3 as 3; a host that truncates so itself cannot be caught by the
        FMU, which sees only the wrapped value) or ``kind`` is not supported.
    """
    beyond = None
    try:
        if kind == "Real":
            if isinstance(value, bool):
                raise TypeError
            return float(value)
        if kind in ("Integer", "Enumeration"):
            if isinstance(value, (bool, float)) and not float(value).is_integer():
                raise TypeError
            number = int(value)
            if INTEGER_RANGE[0] <= number <= INTEGER_RANGE[1]:
                return number
            beyond = number                     # fmpy's ctypes would wrap it silently (2**32 + 3 -> 3)
        if kind == "Boolean":
            if isinstance(value, str):
                if value.strip().lower() not in ("true", "false", "1", "0"):
                    raise TypeError
                return value.strip().lower() in ("true", "1")
            if value not in (True, False, 0, 1):
                raise TypeError
            return bool(value)
        if kind == "String":
            if not isinstance(value, str):
                raise TypeError
            return value
    except (TypeError, ValueError):
        pass
    else:
        if beyond is not None:
            raise ValueError(f"{what} = {beyond} is out of range: an FMI {kind} is a 32-bit integer, "
                             f"{INTEGER_RANGE[0]}..{INTEGER_RANGE[1]}")
        raise ValueError(f"{what}: unsupported type {kind}")
    raise ValueError(f"{what} is a {kind}, got {value!r}")


@dataclass
class BlockSpec:
    """One FMU instance of the diagram.

    Parameters
    ----------
    name : str
        Instance name (unique in the diagram; prefixes recorded columns: ``plant.q[2]``).
    fmu : str or Path
        The FMU file. A relative path is resolved against the diagram's ``fmu_dir``.
    parameters : dict
        Start values to set before initialization, by variable name or vector base.
    sample_time : float or None
        (s) The block is stepped every ``sample_time``, a whole multiple of the run's base step,
        its outputs held in between; None: every base step.
    """

    name: str
    fmu: str | Path
    parameters: dict = field(default_factory=dict)
    sample_time: float | None = None


@dataclass(frozen=True)
class Wire:
    """``src.src_var -> dst.dst_var`` (variable names or vector bases)."""

    src: str
    src_var: str
    dst: str
    dst_var: str

    @classmethod
    def parse(cls, text: str) -> "Wire":
        m = _WIRE.match(text)
        if not m:
            raise ValueError(f"connection {text!r}: expected 'block.variable -> block.variable'")
        return cls(*m.groups())

    def __str__(self) -> str:
        return f"{self.src}.{self.src_var} -> {self.dst}.{self.dst_var}"


@dataclass
class System:
    """Blocks and wires, plus what an experiment needs to run them.

    Parameters
    ----------
    blocks : list of BlockSpec
    wires : list of Wire or str
    fmu_dir : str or Path
        Folder relative FMU paths are resolved against (default: :data:`defaults.FMU_FOLDER`).
    name, description : str
    stop_time, step : float
        Default run length and communication step (s; :mod:`~robofmu.system.defaults`).
    algorithm : one of :data:`defaults.ALGORITHMS`
    extra : dict
        The experiment's other keys (``robot``, ``roles``).
    source : Path or None
        The experiment file the system was read from (None: built in Python).
    """

    blocks: list[BlockSpec]
    wires: list[Wire]
    fmu_dir: Path = Path(defaults.FMU_FOLDER)
    name: str = "system"
    description: str = ""
    stop_time: float = defaults.STOP_TIME
    step: float = defaults.STEP_SIZE
    algorithm: str = defaults.ALGORITHM
    extra: dict = field(default_factory=dict)
    source: Path | None = None

    def __post_init__(self):
        self.wires = [Wire.parse(w) if isinstance(w, str) else w for w in self.wires]
        self.fmu_dir = Path(self.fmu_dir)
        names = [b.name for b in self.blocks]
        dupes = sorted({n for n in names if names.count(n) > 1})
        if dupes:
            raise ValueError(f"{self.name}: instance names must be unique, repeated: {', '.join(dupes)}")

    def block(self, name: str) -> BlockSpec:
        for b in self.blocks:
            if b.name == name:
                return b
        raise KeyError(f"{self.name}: no block {name!r}")

    def fmu_path(self, block: BlockSpec) -> Path:
        path = Path(block.fmu)
        return path if path.is_absolute() else self.fmu_dir / path

    @classmethod
    def from_dict(cls, data: dict, fmu_dir: str | Path | None = None) -> "System":
        """Build from the structure of an experiment file (see ``system/experiments/``)."""
        known = {"name", "description", "stop_time", "step", "algorithm", "blocks", "connections", "fmu_dir"}
        if not isinstance(data.get("blocks"), list):
            raise ValueError("blocks: missing (an array of tables with `name` and `fmu`)")
        blocks = []
        for k, b in enumerate(data["blocks"], 1):
            missing = [key for key in ("name", "fmu") if not isinstance(b, dict) or key not in b]
            if missing:
                raise ValueError(f"blocks[{k}]: missing key {missing[0]!r}")
            sample = b.get("sample_time")
            blocks.append(BlockSpec(b["name"], b["fmu"], dict(b.get("parameters", {})),
                                    None if sample is None else float(sample)))
        return cls(blocks=blocks, wires=list(data.get("connections", [])),
                   fmu_dir=Path(fmu_dir if fmu_dir is not None else data.get("fmu_dir", defaults.FMU_FOLDER)),
                   name=data.get("name", "system"), description=data.get("description", ""),
                   stop_time=float(data.get("stop_time", defaults.STOP_TIME)),
                   step=float(data.get("step", defaults.STEP_SIZE)),
                   algorithm=data.get("algorithm", defaults.ALGORITHM),
                   extra={k: v for k, v in data.items() if k not in known})

