"""FMI-free blocks: each declares its variables and implements output / advance.

A block is built for one robot (a :class:`~robofmu.components.robots.RobotModel`); it declares
its inputs, outputs and parameters in :meth:`Block.declare` (names with FMI structured naming,
``q_ref[1]``.., SI units, descriptions, start values, and for every output the inputs it
depends on) and implements

- :meth:`Block.configure`: validate the parameters (ValueError naming the parameter) and build
  the logic; resets internal state;
- :meth:`Block.output`: outputs at time t from the current inputs and internal state;
- :meth:`Block.advance`: internal state from t to t + h with the inputs held (a refused step
  raises :class:`StepRefused`).

A block is of one of two kinds (as in bdsim): a block with continuous state (plant, controller
integral) derives from :class:`ContinuousBlock`, which makes it implement
:meth:`~ContinuousBlock.continuous_state`, :meth:`~ContinuousBlock.set_continuous_state` and
:meth:`~ContinuousBlock.derivative` (abstract there: a subclass without one of them is refused
when it is defined, and cannot be instantiated), so that a monolithic reference can integrate a
whole diagram as one ODE; any other block derives from :class:`Block` and has no continuous
state (an empty one).

All Real and Boolean values live in one float array :attr:`Block.values`, one slot per declared
scalar in declaration order (a FMU wrapper uses the slot as value reference); Integer and String
parameters live in :attr:`Block.settings`. Vector variables are contiguous:
:meth:`Block.slot` gives the slice.

Subclasses register by ``(kind, variant)`` (a class setting ``abstract = True`` does not): ``Block.__init_subclass__`` rejects a block without a
kind or summary, a kind that robot descriptions do not know (``KNOWN_BLOCKS``, the one list of kinds), a feedthrough block that does not implement :meth:`output`, or one that leaves
an abstract method (a :class:`ContinuousBlock` without its state hooks) unimplemented.
"""
from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import Any, Callable, ClassVar

import numpy as np

from ..parameters import Parameter, ParameterError, resolve
from ..robots.description import KNOWN_BLOCKS, DescriptionError
from ..robots.model import RobotModel

_REGISTRY: dict[tuple[str, str], type["Block"]] = {}


class StepRefused(RuntimeError):
    """A block cannot advance over a step (e.g. its state would turn non-finite)."""


@dataclass(frozen=True)
class Variable:
    """One declared scalar variable.

    Attributes
    ----------
    name : str
        FMI name (``q_ref[2]``, ``kp``).
    base : str
        Vector base (``q_ref``) or the name itself.
    kind : {"Real", "Boolean", "Integer", "String"}
    causality : {"input", "output", "parameter"}
    unit : str or None
    description : str
    start : float, bool, int or str
    depends : tuple of str or None
        Outputs: the inputs they depend on (at every communication point).
    initial_depends : tuple of str or None
        Outputs: the knowns they depend on at initialization (None: every known).
    parameter : Parameter or None
        Scalar parameters: validation rules.
    """

    name: str
    base: str
    kind: str
    causality: str
    unit: str | None
    description: str
    start: Any
    depends: tuple[str, ...] | None = None
    initial_depends: tuple[str, ...] | None = None
    parameter: Parameter | None = None


def quotient_unit(numerator: str, denominator: str) -> str:
    """SI unit of a ratio (a Jacobian entry: task unit over joint unit); "1" for equal units."""
    return "1" if numerator == denominator else f"{numerator}/{denominator}"


def vector_names(base: str, n: int) -> list[str]:
    """``base[1]`` .. ``base[n]``."""
    return [f"{base}[{i}]" for i in range(1, n + 1)]


class Block:
    """Base of every block.

    Parameters
    ----------
    robot : RobotModel
        The block's own model instance of its robot.
    """

    kind: ClassVar[str] = ""
    variant: ClassVar[str] = ""
    feedthrough: ClassVar[bool] = False
    summary: ClassVar[str] = ""
    #: Evaluate times within 1e-9 s of a breakpoint at the breakpoint (sampled use). A monolithic
    #: reference integrating inside one piece of a piecewise profile switches it off.
    snap: bool = True

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        if cls.__dict__.get("abstract", False):
            return
        if not cls.kind or not cls.summary:
            raise TypeError(f"{cls.__name__}: a block needs a `kind` and a `summary`")
        if cls.feedthrough and cls.output is Block.output:
            raise TypeError(f"{cls.__name__}: a direct-feedthrough block must implement output()")
        missing = sorted(name for name in dir(cls)
                         if getattr(getattr(cls, name, None), "__isabstractmethod__", False))
        if missing:
            raise TypeError(f"{cls.__name__}: a block with continuous state must implement "
                            f"{', '.join(f'{name}()' for name in missing)}")
        if cls.kind not in KNOWN_BLOCKS:
            raise TypeError(f"{cls.__name__}: block kind {cls.kind!r} is not one a robot description may "
                            f"list ({', '.join(KNOWN_BLOCKS)}: robots/description.py KNOWN_BLOCKS)")
        key = (cls.kind, cls.variant)
        if key in _REGISTRY:
            raise TypeError(f"{cls.__name__}: block {key} is taken by {_REGISTRY[key].__name__}")
        _REGISTRY[key] = cls

    def __init__(self, robot: RobotModel):
        self.robot = robot
        self.description = robot.description
        self.variables: list[Variable] = []
        self._slots: dict[str, slice] = {}
        self.messages: list[tuple[str, str]] = []
        self.logger: Callable[[str, str], None] = lambda level, text: self.messages.append((level, text))
        self.declare()
        self.index = {v.name: k for k, v in enumerate(self.variables)}
        self.values = np.array([float(v.start) if v.kind in ("Real", "Boolean") else 0.0
                                for v in self.variables])
        self.settings: dict[str, Any] = {v.name: v.start for v in self.variables
                                         if v.kind in ("Integer", "String")}
        self.configured = False

    # -- declaration -----------------------------------------------------------------------------
    def declare(self) -> None:
        raise NotImplementedError

    def _add(self, var: Variable) -> int:
        if any(v.name == var.name for v in self.variables):
            raise TypeError(f"{type(self).__name__}: variable {var.name!r} declared twice")
        self.variables.append(var)
        return len(self.variables) - 1

    def real(self, name: str, causality: str, unit: str, description: str, start: float = 0.0,
             depends=None, initial_depends=None, low: float | None = None,
             high: float | None = None, above: float | None = None) -> int:
        """Declare a scalar Real; returns its slot. Parameters get bounds: ``low`` and ``high``
        inclusive, ``above`` exclusive."""
        rule = (Parameter(name, "Real", unit, description, start, low, high, above=above)
                if causality == "parameter" else None)
        return self._add(Variable(name, name, "Real", causality, unit, description, float(start),
                                  _tuple(depends), _tuple(initial_depends), rule))

    def reals(self, base: str, n: int, causality: str, units, description, starts=None,
              depends=None, initial_depends=None) -> slice:
        """Declare ``base[1]`` .. ``base[n]``; returns their slice of :attr:`values`.

        ``units`` is one unit or one per element; ``description`` a format string with ``{i}``
        (1-based) or a callable of i; ``depends`` / ``initial_depends`` lists or callables of i.
        """
        units = [units] * n if isinstance(units, str) else list(units)
        starts = [0.0] * n if starts is None else [float(s) for s in starts]
        if len(units) != n or len(starts) != n:
            raise TypeError(f"{type(self).__name__}: {base}: need {n} units and start values")
        first = len(self.variables)
        for i in range(1, n + 1):
            text = description(i) if callable(description) else description.format(i=i)
            dep = depends(i) if callable(depends) else depends
            idep = initial_depends(i) if callable(initial_depends) else initial_depends
            self._add(Variable(f"{base}[{i}]", base, "Real", causality, units[i - 1], text,
                               starts[i - 1], _tuple(dep), _tuple(idep)))
        self._slots[base] = slice(first, first + n)
        return self._slots[base]

    def real_matrix(self, base: str, rows: int, cols: int, causality: str, unit, description,
                    depends=None, initial_depends=None) -> slice:
        """Declare ``base[1,1]`` .. ``base[rows,cols]`` row-major (FMI structured naming with two
        indices); returns their slice of :attr:`values` (reshape to (rows, cols)).

        ``unit``, ``description``, ``depends`` and ``initial_depends`` are callables of (i, j)
        (1-based) or one value for every element."""
        first = len(self.variables)
        for i in range(1, rows + 1):
            for j in range(1, cols + 1):
                pick = lambda f: f(i, j) if callable(f) else f
                self._add(Variable(f"{base}[{i},{j}]", base, "Real", causality, pick(unit),
                                   pick(description), 0.0, _tuple(pick(depends)),
                                   _tuple(pick(initial_depends))))
        self._slots[base] = slice(first, first + rows * cols)
        return self._slots[base]

    def joint_positions(self, base: str, description: str) -> slice:
        """Declare a joint-position input vector ``base[j]`` (joint units), starting at the robot's
        ``home`` configuration (q = 0 may be a singularity); ``description``: with ``{i}``."""
        robot = self.robot
        return self.reals(base, robot.n, "input", robot.joint_units(0), description,
                          starts=robot.configuration("home"))

    def boolean(self, name: str, causality: str, description: str, start: bool = False,
                depends=None, initial_depends=None) -> int:
        return self._add(Variable(name, name, "Boolean", causality, None, description, bool(start),
                                  _tuple(depends), _tuple(initial_depends)))

    def setting(self, parameter: Parameter, start) -> None:
        """Declare an Integer or String parameter from its :class:`Parameter`."""
        self._add(Variable(parameter.name, parameter.name, parameter.kind, "parameter", None,
                           parameter.description, start, parameter=parameter))

    def declare_parameter(self, parameter: Parameter, start) -> None:
        """Declare any scalar parameter from its :class:`Parameter` (start: the description's value)."""
        if parameter.kind == "Real":
            self._add(Variable(parameter.name, parameter.name, "Real", "parameter", parameter.unit,
                               parameter.description, float(start), parameter=parameter))
        else:
            self.setting(parameter, start)

    def slot(self, base: str) -> slice:
        """Slice of a vector variable in :attr:`values`."""
        return self._slots[base]

    def names(self, base: str) -> list[str]:
        s = self._slots[base]
        return [v.name for v in self.variables[s]]

    # -- values ----------------------------------------------------------------------------------
    def set(self, name: str, value) -> None:
        """Set a variable by name (or a vector by base) before configuring or as an input."""
        if name in self._slots:
            s = self._slots[name]
            values = np.asarray(value, dtype=float).reshape(-1)
            if values.shape[0] != s.stop - s.start:
                raise ValueError(f"{name}: needs {s.stop - s.start} values, got {values.shape[0]}")
            self.values[s] = values
            return
        try:
            k = self.index[name]
        except KeyError:
            raise KeyError(f"{self.kind} block of {self.description.name!r}: no variable {name!r}") from None
        var = self.variables[k]
        if var.kind in ("Real", "Boolean"):
            self.values[k] = float(value)
        else:
            self.settings[name] = value

    def get(self, name: str):
        """A variable's value by name (a vector base gives an array)."""
        if name in self._slots:
            return self.values[self._slots[name]].copy()
        var = self.variables[self.index[name]]
        if var.kind == "Real":
            return float(self.values[self.index[name]])
        if var.kind == "Boolean":
            return bool(self.values[self.index[name]])
        return self.settings[name]

    def parameter(self, name: str):
        """A scalar parameter's value, validated by its declaration (ValueError naming it)."""
        var = self.variables[self.index[name]]
        value = self.settings[name] if name in self.settings else float(self.values[self.index[name]])
        return var.parameter.validate(value) if var.parameter is not None else value

    def finite_vector(self, base: str, above: float | None = None) -> np.ndarray:
        """A vector parameter, every element finite (and > ``above`` if given); ValueError naming
        the first bad element."""
        values = self.values[self._slots[base]]
        bad = ~np.isfinite(values) if above is None else ~(np.isfinite(values) & (values > above))
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            rule = "finite" if above is None else f"> {above:g}"
            raise ValueError(f"parameter {base}[{k + 1}] = {values[k]:g} is invalid: must be {rule}")
        return values.copy()

    def table_values(self, table: str, declared: tuple[Parameter, ...], given: dict) -> dict:
        """``declared`` resolved from a description table (``"trajectory"``, ``"ik"``);
        DescriptionError naming the file and the key."""
        try:
            return resolve(declared, given)
        except ParameterError as exc:
            raise DescriptionError(self.description.path, f"{table}.{exc.name}", exc.problem) from None

    def table_error(self, table: str, key: str, problem: str):
        """Raise DescriptionError for ``table.key`` of this robot's description."""
        raise DescriptionError(self.description.path, f"{table}.{key}", problem)

    def warn(self, text: str) -> None:
        self.logger("warning", text)

    # -- hooks -----------------------------------------------------------------------------------
    def configure(self) -> None:
        """Validate parameters and build the logic; resets internal state."""
        self.configured = True

    def output(self, t: float) -> None:
        """Compute the outputs at time ``t`` (s) into :attr:`values`."""

    def advance(self, t: float, h: float) -> None:
        """Advance internal state from ``t`` to ``t + h`` with the inputs held."""

    def breakpoints(self) -> np.ndarray:
        """Instants (s) where this block's outputs or derivatives jump as functions of time."""
        return np.zeros(0)

    def nominal_stop_time(self) -> float | None:
        """A sensible default stop time (s) for the block alone, e.g. a profile's end; None: none."""
        return None

    def events(self) -> dict[str, float]:
        """Named instants of the block's schedule (s), e.g. when a gripper closes."""
        return {}

    def internal_state(self) -> dict:
        """State beyond :attr:`values` and :attr:`settings`, JSON-compatible."""
        return {}

    def set_internal_state(self, state: dict) -> None:
        pass

    # -- continuous state (monolithic reference): none; see ContinuousBlock ------------------------
    def continuous_state(self) -> np.ndarray:
        """The block's continuous state: empty (a block with one is a :class:`ContinuousBlock`)."""
        return np.zeros(0)

    def set_continuous_state(self, x: np.ndarray) -> None:
        pass

    def derivative(self, t: float) -> np.ndarray:
        """d/dt of the (empty) continuous state."""
        return np.zeros(0)


class ContinuousBlock(Block, metaclass=abc.ABCMeta):
    """Base of every block with continuous state x (the plant's joint positions and velocities,
    the controller's error integral): it says so by deriving from this class, which makes it
    implement the three hooks a monolithic reference integrates the diagram with (one ODE,
    ``dx/dt = derivative(t)`` of every such block, the inputs from the other blocks).

    Co-simulated alone, the block still advances x itself (:meth:`Block.advance`).
    """

    abstract = True

    @abc.abstractmethod
    def continuous_state(self) -> np.ndarray:
        """The block's continuous state x, shape (s,) (a copy)."""

    @abc.abstractmethod
    def set_continuous_state(self, x: np.ndarray) -> None:
        """Set the continuous state x (shape (s,)), as the integrator of a monolithic reference does."""

    @abc.abstractmethod
    def derivative(self, t: float) -> np.ndarray:
        """dx/dt at time ``t`` from x and the current inputs, shape (s,)."""


def _tuple(value):
    return None if value is None else tuple(value)


def block_class(kind: str, variant: str = "") -> type[Block]:
    """The registered block class of ``kind`` (and ``variant``)."""
    try:
        return _REGISTRY[(kind, variant)]
    except KeyError:
        known = ", ".join(f"{k}:{v}" if v else k for k, v in sorted(_REGISTRY))
        raise ValueError(f"no block {kind!r}{' variant ' + repr(variant) if variant else ''}; known: {known}") from None


def registered() -> list[tuple[str, str]]:
    return sorted(_REGISTRY)
