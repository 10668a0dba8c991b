"""The master's FMI gateway: the FMI 2.0 calls of its loop, bound once, over preallocated buffers.

fmpy instantiates, initializes, terminates and frees the FMUs (:class:`~robofmu.system.fmu.FMUInstance`);
between those, every FMI call the master makes at a communication point goes through this small
gateway next to fmpy, without fmpy's per-call Python wrapper:

- :class:`Fmi2Functions`: fmi2GetReal, fmi2SetReal, fmi2GetBoolean, fmi2SetBoolean and
  fmi2DoStep of one instance, taken from the FMU's shared library as fmpy loaded it;
- :class:`Port` (:func:`output_port`): the value references and ctypes views of one batched get
  or set of one type on one block: one call per block and type, not per variable;
- :class:`Inputs`: a block's wired inputs of one phase and the signals their values come from;
  :class:`Ports`: a block's two output ports and two input phases;
- :func:`getters`, :func:`setters`, :func:`stepper`: those calls as :data:`Call` tuples,
  ``(function, arguments, block, call)``: the loop makes ``status = function(*arguments)`` and
  raises :func:`failed` (a :class:`Failure`) when the status is fmi2Error or worse.

No allocation per step: the master's signal vectors, the ports' buffers and every argument
(arrays, counts, the component, the step sizes; the time is one ``fmi2Real`` whose value the
loop sets per step) are made once, when a run is laid out, each already converted to the
parameter ctypes passes (:class:`Fmi2Functions`); values move between FMUs in place: one
fmi2GetReal per block into a signal vector, one fmi2SetReal per block from it.
"""
from __future__ import annotations

import ctypes
import operator
from typing import NamedTuple

import fmpy
import numpy as np
from fmpy.fmi2 import fmi2Boolean, fmi2Component, fmi2Real, fmi2Status, fmi2True, fmi2ValueReference

from robofmu.system.call_list import Batch, Record
from robofmu.system.plan import Link
from robofmu.system.fmu import status_name

__all__ = ["Call", "Failure", "Fmi2Functions", "Inputs", "Port", "Ports", "failed", "getters", "output_port",
           "setters", "stepper"]

#: The C type of a port's values by its buffer's dtype (fmi2Real: float64; fmi2Boolean: int32).
_CTYPES = {np.dtype(np.float64): fmi2Real, np.dtype(np.int32): fmi2Boolean}

#: One call of the loop: ``(function, arguments, block, call, record)``. ``function(*arguments)``
#: returns the fmi2Status as an int (a ctypes function with its converted arguments, or a Python
#: function of none that makes the call, or returns fmi2OK when there is nothing to set); ``block``
#: (the instance) and ``call`` (``"fmi2GetReal"``) name the :class:`Failure`; ``record`` is the
#: same call for the C call list (:class:`~robofmu.system.call_list.Record`), which makes a list
#: of them in one ctypes call (:func:`~robofmu.system.call_list.batch`: then ``block`` is its
#: :class:`~robofmu.system.call_list.Batch`). A plain tuple: the loop unpacks it in one bytecode.
Call = tuple


class Failure(Exception):
    """A block failed: an FMI call returned an error status (``call`` set), or an output is bad.

    Parameters
    ----------
    block : str
        The instance.
    message : str
        The status in lower case (``"error"``) when ``call`` is set, else what is wrong.
    call : str, optional
        The FMI function that failed (``"fmi2DoStep"``).
    """

    def __init__(self, block: str, message: str, call: str | None = None):
        super().__init__(message)
        self.block = block
        self.message = message
        self.call = call


class Port:
    """Preallocated ctypes views for one batched get or set of one type on one block.

    Parameters
    ----------
    references : list of int
        Value references, length n.
    buffer : ndarray, shape (n,)
        float64 for Real, int32 for Boolean; the FMI call reads or writes it in place.

    Attributes
    ----------
    count : int
        n.
    references : ctypes array of fmi2ValueReference
        The value references (one element when n = 0).
    buffer : ndarray
        As given.
    values : ctypes array or None
        ``buffer``'s memory as fmi2Real or fmi2Boolean (None when n = 0).
    arguments : tuple
        The call's last three arguments (``vr``, ``nvr``, ``value``) as ctypes parameters, made
        once (:class:`Fmi2Functions`); () when n = 0.
    """

    def __init__(self, references: list[int], buffer: np.ndarray):
        self.count = len(references)
        self.references = (fmi2ValueReference * max(self.count, 1))(*references)
        self.buffer = buffer
        self.values = (_CTYPES[buffer.dtype] * self.count).from_buffer(buffer) if self.count else None
        self.arguments = ((ctypes.byref(self.references), ctypes.c_size_t.from_param(self.count),
                           ctypes.byref(self.values)) if self.count else ())


def output_port(references: list[int], signals: np.ndarray, rows: list[int]) -> Port:
    """The port reading one block's outputs of one type straight into a signal vector.

    Parameters
    ----------
    references : list of int
        The outputs' value references, in the order of ``rows``.
    signals : ndarray
        The master's signal vector of their type.
    rows : list of int
        Consecutive indices of ``signals`` (a block's outputs are contiguous); may be empty.

    Returns
    -------
    Port
        Its buffer is the view ``signals[rows[0] : rows[-1] + 1]`` (an empty array if no rows).
    """
    return Port(references, signals[rows[0]:rows[-1] + 1] if rows else np.zeros(0, dtype=signals.dtype))


class Inputs:
    """The wired inputs of one block fed in one phase: ports, and where in the signal vectors
    their values come from.

    Real inputs whose sources are consecutive signals (a wired vector) are set straight from
    the signal vector (``real_in_place``: the port's buffer is a view of it), others through a
    buffer they are gathered into.

    Parameters
    ----------
    links : list of Link
        The block's scalar connections of this phase.
    variables : dict of str to fmpy ScalarVariable
        The block's variables by name.
    real_index, boolean_index : dict of (str, str) to int
        The index in the signal vector of each ``(instance, output)``.
    real_signals : ndarray
        The master's Real signal vector.

    Attributes
    ----------
    real, boolean : Port
        The Real and the Boolean inputs.
    real_sources, boolean_sources : ndarray of intp
        Their values' indices in the signal vectors.
    real_in_place : bool
        ``real``'s buffer is a view of ``real_signals``.
    """

    def __init__(self, links: list[Link], variables: dict, real_index: dict, boolean_index: dict,
                 real_signals: np.ndarray):
        real_links = [link for link in links if variables[link.input].type == "Real"]
        boolean_links = [link for link in links if variables[link.input].type == "Boolean"]
        self.real_sources = np.array([real_index[(link.source, link.output)] for link in real_links],
                                     dtype=np.intp)
        sources = self.real_sources
        self.real_in_place = bool(sources.size) and bool(np.all(sources == sources[0] + np.arange(sources.size)))
        buffer = (real_signals[sources[0]:sources[0] + sources.size] if self.real_in_place
                  else np.zeros(len(real_links)))
        self.real = Port([variables[link.input].valueReference for link in real_links], buffer)
        self.boolean = Port([variables[link.input].valueReference for link in boolean_links],
                            np.zeros(len(boolean_links), dtype=np.int32))
        self.boolean_sources = np.array([boolean_index[(link.source, link.output)] for link in boolean_links],
                                        dtype=np.intp)


class Ports(NamedTuple):
    """One block's ports in a run.

    Attributes
    ----------
    get_real, get_boolean : Port
        Its outputs read (:func:`output_port`).
    early : Inputs
        Its inputs from blocks evaluated before it, set before its outputs are read.
    late : Inputs
        Its inputs from blocks evaluated after it, set once the pass is over.
    """

    get_real: Port
    get_boolean: Port
    early: Inputs
    late: Inputs


# The calls' C types (FMI 2.0 fmi2FunctionTypes.h), which every argument is made as once:
#   fmi2GetReal / fmi2SetReal (fmi2Component, const fmi2ValueReference*, size_t, fmi2Real*)
#   fmi2GetBoolean / fmi2SetBoolean (fmi2Component, const fmi2ValueReference*, size_t, fmi2Boolean*)
#   fmi2DoStep (fmi2Component, fmi2Real, fmi2Real, fmi2Boolean)


class Fmi2Functions:
    """The FMI 2.0 functions of the master's loop for one instance, bound once.

    Called with arguments already of their C types (listed above), converted once into the
    parameter objects ctypes passes: ``from_param`` of the C type for a value (the component,
    a count, a step size, fmi2True), ``byref`` for an array. A ctypes instance passed as an
    argument (``c_size_t(n)``) is converted into a new parameter object at every call, and
    without ``argtypes`` a Python int would go as a C int, so nothing else may be passed; the
    time alone is an ``fmi2Real`` instance, its value set per step. Binding without
    ``argtypes`` halved the Python side of a call; the parameters made once take another third
    off it (callgrind: about 3.8k -> 2.4k instructions for four arguments).

    Taken from the FMU's shared library as fmpy loaded it: the ``dll`` (a ``ctypes.CDLL``) and
    ``component`` attributes of fmpy's ``FMU2Slave`` (public attributes, not fmpy's private
    table of wrapped functions). ``dll[name]`` makes a new ctypes function object, so the
    prototypes set here (from the FMI 2.0 header) leave fmpy's own untouched. They are bound
    as Python-API functions (``ctypes.PyDLL`` on the same handle): the calling thread keeps the
    GIL through each call. A pythonfmu FMU takes the GIL again inside every call anyway; released
    and retaken thousands of times a second, it would go to any other thread of the process that
    waits for it (a Dask worker's event loop), and each step would queue behind that thread.

    Parameters
    ----------
    slave : fmpy.fmi2.FMU2Slave
        The instantiated FMU (:attr:`FMUInstance.slave <robofmu.system.fmu.FMUInstance>`).

    Attributes
    ----------
    component : fmi2Component
        The instance.
    argument : ctypes parameter
        ``component`` as the calls' first argument (``fmi2Component.from_param``).
    get_real, set_real, get_boolean, set_boolean, do_step : ctypes function
        fmi2GetReal, fmi2SetReal, fmi2GetBoolean, fmi2SetBoolean, fmi2DoStep; each returns the
        fmi2Status as an int.

    Raises
    ------
    RuntimeError
        If the installed fmpy does not provide those attributes (a clear message, at the first
        run, instead of an AttributeError in the loop).
    """

    def __init__(self, slave):
        library = getattr(slave, "dll", None)
        component = getattr(slave, "component", None)
        if not isinstance(library, ctypes.CDLL) or component is None:
            raise RuntimeError(
                f"fmpy {getattr(fmpy, '__version__', '?')}: FMU2Slave has no loaded shared library "
                "`dll` (ctypes.CDLL) and instance `component`; the master binds fmi2GetReal, "
                "fmi2SetReal, fmi2GetBoolean, fmi2SetBoolean and fmi2DoStep from them (written "
                "for fmpy 0.3.x)")
        self.component = fmi2Component(component)
        self.argument = fmi2Component.from_param(self.component.value)
        library = ctypes.PyDLL(library._name, handle=library._handle)
        self.get_real = _bind(library, "fmi2GetReal")
        self.set_real = _bind(library, "fmi2SetReal")
        self.get_boolean = _bind(library, "fmi2GetBoolean")
        self.set_boolean = _bind(library, "fmi2SetBoolean")
        self.do_step = _bind(library, "fmi2DoStep")


def _bind(library: ctypes.CDLL, name: str):
    function = library[name]            # no argtypes: see Fmi2Functions (the C types: above it)
    function.restype = fmi2Status
    return function


def failed(block, status: int, call: str | None) -> Failure:
    """The :class:`Failure` of ``call`` on ``block`` that returned ``status`` (fmi2Error or worse);
    ``block`` a :class:`~robofmu.system.call_list.Batch`: of the call in it that failed."""
    if isinstance(block, Batch):
        block, call = block.failed()
    return Failure(block, status_name(status).lower(), call)


def getters(functions: Fmi2Functions, ports: Ports, name: str) -> list[Call]:
    """The calls reading one block's outputs into the signal vectors: one batched fmi2GetReal,
    one fmi2GetBoolean, each only if the block has outputs of that type to read.

    Parameters
    ----------
    functions : Fmi2Functions
        The block's.
    ports : Ports
        The block's (``get_real``, ``get_boolean``).
    name : str
        The instance, for :class:`Failure`.

    Returns
    -------
    list of Call
    """
    return [(function, (functions.argument, *port.arguments), name, call,
             Record(function, functions.component.value, port.references, port.count, port.values))
            for port, function, call in ((ports.get_real, functions.get_real, "fmi2GetReal"),
                                         (ports.get_boolean, functions.get_boolean, "fmi2GetBoolean"))
            if port.count]


def setters(functions: Fmi2Functions, inputs: Inputs, real_signals: np.ndarray,
            boolean_signals: np.ndarray, name: str) -> list[Call]:
    """The calls setting one block's inputs of one phase from the signal vectors.

    Real inputs: one batched fmi2SetReal, straight from ``real_signals`` if their sources are
    consecutive, else after gathering them into the port's buffer. Boolean inputs: one
    fmi2SetBoolean, only when their values changed since the last one made through these calls
    (discrete inputs; the first one is always made).

    Parameters
    ----------
    functions, name
        As for :func:`getters`.
    inputs : Inputs
        The block's inputs of the phase.
    real_signals, boolean_signals : ndarray
        The master's signal vectors (never replaced during a run).

    Returns
    -------
    list of Call
    """
    calls = []
    real, boolean = inputs.real, inputs.boolean
    if real.count and inputs.real_in_place:
        calls.append((functions.set_real, (functions.argument, *real.arguments), name, "fmi2SetReal",
                      Record(functions.set_real, functions.component.value, real.references, real.count,
                             real.values)))
    elif real.count:
        def set_real(take=real_signals.take, sources=inputs.real_sources, buffer=real.buffer,
                     function=functions.set_real, arguments=(functions.argument, *real.arguments)):
            take(sources, out=buffer)
            return function(*arguments)
        calls.append((set_real, (), name, "fmi2SetReal",
                      Record(functions.set_real, functions.component.value, real.references, real.count,
                             real.values, real_signals, inputs.real_sources)))
    if boolean.count:
        # the sources' values as one int (one input) or a tuple, read without NumPy
        pick = operator.itemgetter(*inputs.boolean_sources.tolist())
        single = boolean.count == 1

        def set_boolean(pick=pick, signals=memoryview(boolean_signals), last=[None], values=boolean.values,
                        function=functions.set_boolean, arguments=(functions.argument, *boolean.arguments)):
            now = pick(signals)
            if now == last[0]:            # discrete inputs: set only when they change
                return 0
            values[:] = (now,) if single else now
            status = function(*arguments)
            if status <= 1:
                last[0] = now
            return status
        calls.append((set_boolean, (), name, "fmi2SetBoolean",
                      Record(functions.set_boolean, functions.component.value, boolean.references, boolean.count,
                             boolean.values, boolean_signals, inputs.boolean_sources,
                             np.zeros(boolean.count, dtype=np.int32), np.zeros(1, dtype=np.int32))))
    return calls


def stepper(functions: Fmi2Functions, name: str, time: ctypes.c_double, size: float) -> Call:
    """The call of one block's fmi2DoStep.

    Parameters
    ----------
    functions, name
        As for :func:`getters`.
    time : fmi2Real
        The communication point (s), its value set by the loop before the call.
    size : float
        The communication step size (s): the block's sample time.

    Returns
    -------
    Call
        fmi2DoStep(time, size, noSetFMUStatePriorToCurrentPoint = fmi2True).
    """
    return (functions.do_step, (functions.argument, time, fmi2Real.from_param(size), _TRUE), name, "fmi2DoStep",
            Record(functions.do_step, functions.component.value, time=time, step=float(size)))


_TRUE = fmi2Boolean.from_param(fmi2True)
