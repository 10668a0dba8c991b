"""The contract of robofmu's FMI libraries with the Python side has one definition, and drift fails.

:mod:`robofmu.components.fmi.contract` defines what the export library (``robofmu_fmi2.c``) and
the front library (``robofmu_front.c``) share with the Python side: file names, the status
category, the marker, the fast path's struct, numbers and registration function. The Python
side imports it; the build renders it as ``robofmu_contract.h`` into the C compile
(:mod:`robofmu.system.packaging.fmi_export.contract_header`). Drift is a failed build, not a fast
path silently switched off at run time:

- a C source that defines a contract item itself (a macro, the struct, a copy of a contract
  string), does not include the header, or lacks a function the Python side calls, is refused;
- a field whose C type does not give the offset and size ctypes gives it fails the compile
  (``_Static_assert``), naming the field; so does a C source using a field or a registration
  signature the contract no longer has;
- a compiled probe reads the C compiler's layout of the struct, which must be ctypes' own.
"""
from __future__ import annotations

import ctypes
import re
import subprocess
import types

import pytest

from robofmu.components.fmi import contract
from robofmu.system.packaging import fmi_export
from robofmu.system.packaging.fmi_export import contract_header

EXPORTS = (contract.MARKER_FUNCTION, contract.REGISTER)


def drifted(**changes) -> types.SimpleNamespace:
    """A copy of the contract with ``changes`` (a test's drifted definition)."""
    names = {name: getattr(contract, name) for name in dir(contract) if not name.startswith("_")}
    names.update(changes)
    if "FAST_SHARED_FIELDS" in changes:
        names["FastShared"] = type("FastShared", (ctypes.Structure,),
                                   {"_fields_": [(n, ctype) for n, ctype, _, _ in changes["FAST_SHARED_FIELDS"]]})
    return types.SimpleNamespace(**names)


def compile_c(tmp_path, source: str, definition=contract, name="probe.c", shared=False):
    """``source`` compiled with the header of ``definition`` as the build compiles: the result."""
    folder = tmp_path / "include"
    contract_header.write_header(folder, definition)
    path = tmp_path / name
    path.write_text(source)
    out = tmp_path / ("probe.so" if shared else "probe")
    command = fmi_export._compiler() + (["-shared", "-fPIC"] if shared else []) + [
        "-Wall", "-Werror", f"-I{folder}", f"-I{fmi_export.SOURCE.parent}", "-o", str(out), str(path), "-ldl", "-pthread"]
    return subprocess.run(command, capture_output=True, text=True, timeout=300), out


# -- one definition -------------------------------------------------------------------------------------
def test_the_python_side_takes_every_name_from_the_contract():
    for name in ("STATUS_CATEGORY", "STOCK_LIBRARY", "MARKER", "RUNTIME_RECORD", "PLATFORM", "FRONT_BEHIND"):
        assert getattr(fmi_export, name) is getattr(contract, name), name
    assert [(f[0], f[1]) for f in contract.FastShared._fields_] == [(f[0], f[1]) for f in contract.FAST_SHARED_FIELDS]
    for name in contract.C_CONSTANTS:
        assert isinstance(getattr(contract, name), (str, int)), name


def test_the_c_sources_keep_the_contract_and_the_library_is_built_with_its_header():
    for source in (fmi_export.SOURCE, fmi_export.FRONT_SOURCE):
        assert contract_header.source_problems(source, fmi_export.EXPORTS[source.name]) == [], source
        fmi_export.check_source(source)
        assert not source.with_name(contract_header.HEADER_NAME).exists()       # only the generated one
    built = fmi_export.library()
    assert (built.parent / contract_header.HEADER_NAME).read_text() == contract_header.header()


def test_every_constant_reaches_c_with_its_value(tmp_path):
    """The header's macros, printed by a compiled program, are the contract's values."""
    prints = "\n".join(f'    printf("%s\\n", {name});' if isinstance(getattr(contract, name), str)
                       else f'    printf("%lld\\n", (long long){name});' for name in contract.C_CONSTANTS)
    done, program = compile_c(tmp_path, f'#include <stdio.h>\n#include "{contract_header.HEADER_NAME}"\n'
                                         f"int main(void) {{\n{prints}\n    return 0;\n}}\n")
    assert done.returncode == 0, done.stderr
    printed = subprocess.run([str(program)], capture_output=True, text=True, check=True).stdout.split("\n")[:-1]
    assert printed == [str(getattr(contract, name)) for name in contract.C_CONSTANTS]


def test_fast_shared_has_the_c_compilers_layout(tmp_path):
    """A probe compiled as the library is prints each field's offset and size and the struct's
    size: what ctypes gives the slave's struct."""
    lines = [f'    printf("{name} %zu %zu\\n", offsetof(FastShared, {name}), sizeof(((FastShared*)0)->{name}));'
             for name, *_ in contract.FAST_SHARED_FIELDS]
    done, program = compile_c(tmp_path, f'#include <stdio.h>\n#include "{contract_header.HEADER_NAME}"\n'
                                         "int main(void) {\n" + "\n".join(lines)
                                         + '\n    printf("sizeof %zu\\n", sizeof(FastShared));\n    return 0;\n}\n')
    assert done.returncode == 0, done.stderr
    printed = subprocess.run([str(program)], capture_output=True, text=True, check=True).stdout.splitlines()
    expected = [f"{name} {getattr(contract.FastShared, name).offset} {getattr(contract.FastShared, name).size}"
                for name, *_ in contract.FAST_SHARED_FIELDS]
    assert printed == expected + [f"sizeof {ctypes.sizeof(contract.FastShared)}"]


# -- drift fails --------------------------------------------------------------------------------------
def test_a_field_whose_c_type_drifts_from_ctypes_fails_the_compile_naming_it(tmp_path):
    fields = [(n, t, "int64_t" if n == "dirty" else c, w) for n, t, c, w in contract.FAST_SHARED_FIELDS]
    header = contract_header.header(drifted(FAST_SHARED_FIELDS=tuple(fields)))
    assert "int64_t dirty;" in header
    done, _ = compile_c(tmp_path, f'#include "{contract_header.HEADER_NAME}"\nint main(void) {{ return 0; }}\n',
                        drifted(FAST_SHARED_FIELDS=tuple(fields)))
    assert done.returncode != 0
    assert "FastShared.dirty: not at offset 68 with size 4, as ctypes has it" in done.stderr, done.stderr


@pytest.mark.parametrize("change, complaint", [
    ("field", r"inputs_checked"),
    ("register", r"robofmu_fast_register"),
], ids=["a-field-renamed", "the-registration-signature-changed"])
def test_the_export_library_does_not_compile_against_a_drifted_contract(tmp_path, change, complaint):
    if change == "field":
        fields = tuple((("checked_inputs" if n == "inputs_checked" else n), t, c, w)
                       for n, t, c, w in contract.FAST_SHARED_FIELDS)
        definition = drifted(FAST_SHARED_FIELDS=fields)
    else:
        definition = drifted(REGISTER_PARAMETERS=contract.REGISTER_PARAMETERS[:-1])
    done, _ = compile_c(tmp_path, fmi_export.SOURCE.read_text(), definition, name=fmi_export.SOURCE.name, shared=True)
    assert done.returncode != 0
    assert re.search(complaint, done.stderr), done.stderr
    # the same source against the contract itself compiles (the drift, not the probe, fails)
    done, _ = compile_c(tmp_path, fmi_export.SOURCE.read_text(), name=fmi_export.SOURCE.name, shared=True)
    assert done.returncode == 0, done.stderr


def _edits():
    """(id, edit of robofmu_fmi2.c's text, what the check says)."""
    return [
        ("own-macro", lambda s: s.replace('#include "robofmu_contract.h"',
                                          '#include "robofmu_contract.h"\n#define FAST_VERSION 3'),
         "it defines FAST_VERSION itself"),
        ("own-struct", lambda s: s.replace('#include "robofmu_contract.h"',
                                           '#include "robofmu_contract.h"\ntypedef struct { int x; } FastShared;'),
         "it defines FastShared itself"),
        ("copied-marker", lambda s: s.replace("return MARKER;", 'return "robofmu FMI 2.0 export library";'),
         'the string "robofmu FMI 2.0 export library" copies contract.MARKER'),
        ("copied-switch", lambda s: s.replace("getenv(FAST_PATH_SWITCH)", 'getenv("ROBOFMU_FMI_FAST_PATH")'),
         "copies contract.FAST_PATH_SWITCH"),
        ("copied-not-utf8", lambda s: s.replace("memcpy(hex, NOT_UTF8,", 'memcpy(hex, "\\x1brobofmu:not-utf8:",'),
         "copies contract.NOT_UTF8"),
        ("no-include", lambda s: s.replace('#include "robofmu_contract.h"', ""),
         'it does not #include "robofmu_contract.h"'),
        ("renamed-register", lambda s: s.replace("EXPORT int robofmu_fast_register(", "EXPORT int robofmu_fast_enrol("),
         "it does not define robofmu_fast_register()"),
    ]


@pytest.mark.parametrize("edit, complaint", [e[1:] for e in _edits()], ids=[e[0] for e in _edits()])
def test_a_c_source_with_a_copy_of_the_contract_is_refused(tmp_path, edit, complaint):
    original = fmi_export.SOURCE.read_text()
    text = edit(original)
    assert text != original
    copy = tmp_path / fmi_export.SOURCE.name
    copy.write_text(text)
    problems = contract_header.source_problems(copy, EXPORTS)
    assert any(complaint in p for p in problems), problems
    with pytest.raises(fmi_export.FmiExportError, match="breaks the contract") as info:
        fmi_export.check_source(copy)
    assert complaint in str(info.value)


def test_the_build_refuses_a_drifted_source_loudly(tmp_path, monkeypatch):
    """library() fails on the copy before compiling: no library is built to run without a fast path."""
    monkeypatch.setenv("ROBOFMU_CACHE", str(tmp_path / "cache"))
    copy = tmp_path / "src" / fmi_export.SOURCE.name
    copy.parent.mkdir()
    copy.write_text(fmi_export.SOURCE.read_text().replace("return MARKER;", 'return "robofmu FMI 2.0 export library";'))
    with pytest.raises(fmi_export.FmiExportError, match="copies contract.MARKER"):
        fmi_export.library(source=copy)
    assert not list((tmp_path / "cache").rglob("*.so"))


def test_a_header_beside_the_source_is_refused(tmp_path):
    """``#include "robofmu_contract.h"`` finds a file beside the source before the include path:
    a stale copy there would win over the generated header."""
    copy = tmp_path / fmi_export.SOURCE.name
    copy.write_text(fmi_export.SOURCE.read_text())
    fmi_export.check_source(copy)
    (tmp_path / contract_header.HEADER_NAME).write_text(contract_header.header())
    with pytest.raises(fmi_export.FmiExportError, match="lies beside it"):
        fmi_export.check_source(copy)
