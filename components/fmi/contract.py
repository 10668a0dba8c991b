"""The contract of robofmu's FMI libraries with the Python side: its one definition.

robofmu's export library (``system/packaging/fmi_export/robofmu_fmi2.c``, in front of
pythonfmu's in every FMU) and the slave (:mod:`.base`) agree on names, numbers, a function's
signature and a struct's layout; robofmu's build and tools agree with the library on file
names. Every one of them is defined here and nowhere else:

- the Python side imports them (the slave, bundled in every FMU, from here; the build and its
  tools through ``robofmu.system.packaging.fmi_export``);
- the C side includes them: the build renders this module as the header ``robofmu_contract.h``
  (``robofmu.system.packaging.fmi_export.contract_header``) into the compile of each C library, and
  refuses a C source that defines one of them itself. The header asserts at compile time
  (``_Static_assert``) that the C compiler lays :class:`FastShared` out as ctypes does here, and
  declares :data:`REGISTER` with the parameters of :data:`REGISTER_PARAMETERS`, so that a
  definition of another signature does not compile.

The slave's registration still hands the library :data:`FAST_VERSION` and the struct's size
(a run-time handshake: the library refuses another), but the build guarantees both agree.

This module imports nothing but ctypes: the build imports it without pythonfmu's machinery.
"""
from __future__ import annotations

import ctypes

__all__ = ["C_CONSTANTS", "FAST_CALLS", "FAST_CHECK", "FAST_GET_BOOLEAN", "FAST_GET_REAL", "FAST_MESSAGES",
           "FAST_OK", "FAST_PATH_SWITCH", "FAST_SHARED_FIELDS", "FAST_VERSION", "FRONT_BEHIND", "FastShared",
           "MARKER", "MARKER_FUNCTION", "NOT_UTF8", "PLATFORM", "REGISTER", "REGISTER_PARAMETERS",
           "RUNTIME_RECORD", "STATUS_CATEGORY", "STOCK_LIBRARY"]

# -- the FMU's files --------------------------------------------------------------------------------
#: The only platform folder of a FMU's ``binaries``: the platform robofmu's library is built for.
PLATFORM = "linux64"
#: pythonfmu's export library, beside robofmu's in ``binaries/linux64`` (robofmu's loads it).
STOCK_LIBRARY = "libpythonfmu-export.so"
#: The Python runtime a FMU was built for, in its ``resources`` (``key=value`` lines: version,
#: program, library): written by the build, read by the library (point 5 of its header comment).
RUNTIME_RECORD = "robofmu_python.txt"
#: What the library answers from its marker export :data:`MARKER_FUNCTION` (pythonfmu's has none).
MARKER = "robofmu FMI 2.0 export library"
MARKER_FUNCTION = "robofmu_fmi_library"
#: The library behind robofmu's front library in a FMU container (``robofmu_front.c``).
FRONT_BEHIND = "libcontainer-runtime.so"

# -- statuses and values ------------------------------------------------------------------------------
#: A message the slave logs with this category makes the library return the message's status
#: from the FMI call it is logged in (the importer sees pythonfmu's usual category,
#: ``logStatusError``...).
STATUS_CATEGORY = "robofmu:status"
#: A fmi2SetString value that is not valid UTF-8 reaches the slave as this prefix and the hex of
#: its bytes: what the library forwards instead of the raw bytes, which pythonfmu 0.7.0 cannot
#: convert (PyUnicode_FromString fails: fmi2Fatal, the instance damaged).
NOT_UTF8 = "\x1brobofmu:not-utf8:"

# -- the fast path (point 4 of the library's header comment) ------------------------------------------
#: The environment variable that, set to ``0`` at instantiation, makes the library refuse the
#: slave's registration: every call then goes through pythonfmu.
FAST_PATH_SWITCH = "ROBOFMU_FMI_FAST_PATH"
#: The layout version of :class:`FastShared`, checked at registration with the struct's size.
FAST_VERSION = 2
#: What the slave's refresh(), step() and nonfinite() return to the library, as bits: it
#: succeeded; messages wait in its log queue; (refresh() only) it computed the outputs and
#: leaves their check to the library.
FAST_OK, FAST_MESSAGES, FAST_CHECK = 1, 2, 4
#: ``FastShared.call``: the FMI call a refresh() serves.
FAST_GET_REAL, FAST_GET_BOOLEAN = 1, 2
FAST_CALLS = {FAST_GET_REAL: "fmi2GetReal", FAST_GET_BOOLEAN: "fmi2GetBoolean"}

#: What the library reads and writes of a slave on its fast path, field by field:
#: ``(name, ctypes type, C type, what it holds)``. :class:`FastShared` and the C struct
#: ``FastShared`` are both made from it.
FAST_SHARED_FIELDS = (
    ("version", ctypes.c_uint32, "uint32_t", "FAST_VERSION"),
    ("size", ctypes.c_uint32, "uint32_t", "sizeof(FastShared)"),
    ("values", ctypes.c_void_p, "double*", "the slave's values: values[vr]"),
    ("n", ctypes.c_size_t, "size_t", "their number"),
    ("get_real", ctypes.c_void_p, "const unsigned char*", "per slot: a Real variable"),
    ("get_boolean", ctypes.c_void_p, "const unsigned char*", "per slot: a Boolean variable"),
    ("set_real", ctypes.c_void_p, "const unsigned char*", "per slot: a Real input"),
    ("output", ctypes.c_void_p, "const unsigned char*", "per slot: a Real output"),
    ("saved", ctypes.c_void_p, "double*", "n values: the values as they were before refresh()"),
    ("active", ctypes.c_int32, "int32_t", "initialized and not terminated"),
    ("dirty", ctypes.c_int32, "int32_t", "outputs stale: refresh() before reading them"),
    ("inputs_checked", ctypes.c_int32, "int32_t", "inputs found finite since they were last set"),
    ("call", ctypes.c_int32, "int32_t", "the FMI call of a refresh(): FAST_GET_REAL, FAST_GET_BOOLEAN"),
)


class FastShared(ctypes.Structure):
    """What robofmu's export library reads and writes of a slave on its fast path
    (:data:`FAST_SHARED_FIELDS`; the C struct ``FastShared`` has the same layout). The slave
    owns it and the arrays it points to, as long as it lives; the library uses it between
    fmi2Instantiate and fmi2FreeInstance only."""
    _fields_ = [(name, ctype) for name, ctype, _, _ in FAST_SHARED_FIELDS]


#: The library's registration function, which the slave calls (ctypes) at the end of its
#: construction inside fmi2Instantiate; it returns 1 (C ``int``) if it registered the slave.
REGISTER = "robofmu_fast_register"
#: Its parameters: ``(name, ctypes type the slave passes, C type)``. The last is the context
#: (``contextvars.Context``) in which NumPy ignores floating-point errors, which the library
#: enters around each call, as an address (NULL: none).
REGISTER_PARAMETERS = (
    ("shared", ctypes.c_void_p, "FastShared*"),
    ("refresh", ctypes.py_object, "PyObject*"),
    ("step", ctypes.py_object, "PyObject*"),
    ("nonfinite", ctypes.py_object, "PyObject*"),
    ("quiet", ctypes.c_void_p, "PyObject*"),
)

#: The constants above that the C libraries use, by the same names (the header's macros).
C_CONSTANTS = ("STOCK_LIBRARY", "RUNTIME_RECORD", "MARKER", "FRONT_BEHIND", "STATUS_CATEGORY", "NOT_UTF8",
               "FAST_PATH_SWITCH", "FAST_VERSION", "FAST_OK", "FAST_MESSAGES", "FAST_CHECK", "FAST_GET_REAL",
               "FAST_GET_BOOLEAN")
