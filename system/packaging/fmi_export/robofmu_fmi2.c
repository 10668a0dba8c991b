/* robofmu's FMI 2.0 co-simulation export library: a thin layer in front of pythonfmu's.

   Every robofmu FMU carries, in binaries/linux64/, this library as <modelIdentifier>.so and
   pythonfmu 0.7.0's own export library, unchanged, as libpythonfmu-export.so. The importer
   loads this one; it loads pythonfmu's from its own folder and forwards every FMI function to
   it, changing two things (robofmu.system.packaging.fmi_export explains why; docs/design.md too),
   guarding against a third (point 3) and serving the hot calls of robofmu's slave itself, with
   the same results (point 4):

   1. Statuses. A message the Python slave logs with the category "robofmu:status" makes the
      FMI call during which it is logged return at least the message's status (fmi2Error for a
      refused step, where pythonfmu can only return fmi2Discard; fmi2Error for invalid input to
      any other call, where pythonfmu can only return fmi2OK or, by raising, fmi2Fatal). The
      importer receives the message with the category pythonfmu would have given it
      ("logStatusError", ...).
   2. Logging. pythonfmu drops every message while debug logging is off. Here pythonfmu always
      logs, and this layer filters: messages of status fmi2Warning and above always reach the
      importer's logger; fmi2OK messages only while loggingOn (fmi2Instantiate or
      fmi2SetDebugLogging) is true and, if categories were set, their category is one of them
      (or "logAll" is). A '%' in a message is doubled: the logger takes it as a format.
   3. Process exit. pythonfmu keeps its Python state in a static std::shared_ptr released by two
      hooks: its C++ destructor (run by exit() among the exit handlers) and its unload hook (run
      after them by exit(), first by dlclose). At exit() the destructor frees the state without
      emptying the pointer, and the hook then writes into the freed block (system/interop/libcosim.py,
      "Process exit"). So, as it loads pythonfmu's library, this layer registers pythonfmu's own
      finalizePythonInterpreter (the hook's body: it empties the pointer, releasing the state)
      as an exit handler owned by that library (__cxa_atexit with the library's __dso_handle,
      read from its symbol table). exit() runs it before the library's C++ destructors, which
      were registered as it loaded; both hooks then find nothing to release. Unloading the
      library runs it after the hook (nothing left) and drops it. The state lives as long as
      without this layer, only its release at exit comes first: in a Python host it is a thread
      that ended when the state was made, released after Py_Finalize without any call into
      Python; in a host that is not Python it is the interpreter pythonfmu started, finalized
      there as pythonfmu's destructor would have. (Releasing it when this library unloads
      would finalize that interpreter while the process still needs it: the first copy of
      pythonfmu's library loaded in a process never unloads, and the next FMU would start a
      second interpreter, in which numpy cannot be imported again.)

   4. The fast path. pythonfmu's library makes every FMI call a Python method call looked up by
      name, with Python lists of value references and values built and converted and the log
      queue read back (about 6 µs a call). For the calls of a master's hot loop this layer
      serves robofmu's slave itself, through the FMI functions it exports (nothing else reaches
      the slave): the slave, as it is constructed inside fmi2Instantiate, finds this library
      (the one its FMU's binaries/linux64 holds, already loaded: dlopen with RTLD_NOLOAD) and
      calls robofmu_fast_register with a struct it owns (FastShared: the address and length of
      its float64 `values` array, whose slot is the value reference; a byte per slot for Real
      gettable, Boolean gettable, Real settable as an input; flags it reads and writes as
      attributes: initialized and not terminated, outputs stale (dirty), inputs checked; a byte
      per slot for Real outputs, and an array of n doubles to save the values into), three
      callables, refresh() (bring the outputs up to date, as its get_real does when stale),
      step(t, h) (its do_step) and nonfinite() (hold the saved outputs and report), which catch
      every exception and return 1 if they succeeded, +2 if messages wait in its log queue (+4
      from refresh() or step(): outputs computed, their check left to this layer), and a
      context (contextvars.Context, a copy of the host's at registration) in which NumPy's
      error state is "ignore", entered around every one of those calls (PyContext_Enter, then
      _Exit: what the slave's quietly() does, without the new mapping and token that setting
      the variable in the host's context makes at every call; the slave's Python code runs in
      its own context). A registration outside this library's fmi2Instantiate
      (or fmi2Reset) in the same thread is refused, so is one with another struct version or
      size, or where a Python C-API function below cannot be found (dlsym(RTLD_DEFAULT): the
      functions pythonfmu's library binds to; nothing links libpython), or with the
      environment variable ROBOFMU_FMI_FAST_PATH=0. The component fmi2Instantiate returns keeps
      new references to the callables until fmi2FreeInstance (fmi2Reset: until the slave is
      constructed anew) releases them, holding the GIL, before pythonfmu frees the slave.
      Then, while the slave is initialized and not terminated:
      - fmi2SetReal of Real inputs only writes values[vr], marks the outputs stale and, if a
        value written is not finite, the inputs unchecked: no Python at all;
      - fmi2GetReal of Real variables only and fmi2GetBoolean of Boolean variables only call
        refresh() if the outputs are stale (PyGILState_Ensure: the host may hold the GIL, as
        the master's ctypes.PyDLL calls do, or not, as libcosim's threads), the values saved
        first; if it says +4, the outputs are checked here: all finite, they are current (not
        stale), else nonfinite() is called; then the values are copied (a Boolean is value !=
        0.0); if refresh() failed, zeros / false, as the slave's get_real does;
      - fmi2DoStep calls step(t, h); a refused step is fmi2Discard from pythonfmu, so it is
        here, raised to the logged status (fmi2Error: point 1). The values are saved first:
        a block without feedthrough computes its outputs at t + h in step() (+4), checked
        here as after refresh(): all finite, they are current, so the read that follows
        enters no Python; else the saved outputs are back and stale (the read computes them
        again and reports). The status pythonfmu's
        fmi2GetRealStatus (fmi2LastSuccessfulTime) and fmi2GetBooleanStatus (fmi2Terminated)
        would give after it are kept here and answered.
      When the slave says messages wait, this layer calls pythonfmu's fmi2GetString with no
      value references (the slave's get_string([]) does nothing; pythonfmu releases the
      strings an earlier fmi2GetString returned, which FMI lets the next call do) before
      returning: pythonfmu drains the queue into filter() during the current call, so messages
      are filtered and set the call's status exactly as without the fast path. Every other
      call, and these with a value reference out of range or of another type or causality (so
      the error messages are pythonfmu's and the slave's), before initialization, after
      fmi2Terminate, and in an instance that did not register, goes to pythonfmu as before.
      robofmu_fast_path(c) says whether an instance registered, robofmu_fast_calls(c) how many
      calls it served.

   5. The Python runtime. pythonfmu's library resolves Python's symbols from the process and
      fails to load without them ("undefined symbol: _Py_NoneStruct"), and the interpreter it
      starts finds its standard library and packages from the first python3 on PATH. So this
      layer loads pythonfmu's library at the first fmi2Instantiate, not when it is loaded
      itself, after making sure of the runtime, from the FMU's resources/robofmu_python.txt
      (version, program, library: written by robofmu build; the environment variables
      ROBOFMU_LIBPYTHON and ROBOFMU_PYTHON override library and program):
      - no Python in the process (a host that is not Python): the recorded libpython is loaded
        by its full path with RTLD_NOW | RTLD_GLOBAL;
      - the running Python (Py_GetVersion) must be the recorded version: pythonfmu's library is
        compiled for one;
      - if the interpreter is not initialized yet, it is told it is the recorded program
        (Py_SetProgramName: a venv's bin/python makes it find that venv), before pythonfmu's
        library initializes it.
      A failure returns NULL from fmi2Instantiate with a message that names what is missing and
      `robofmu doctor`.
   6. Calls no host should crash on:
      - fmi2Instantiate checks fmuResourceLocation (file:///path, file:/path,
        file://localhost/path, percent-encoded) names a readable folder holding
        slavemodule.txt, and hands pythonfmu the form it parses ("file://" and the path, spaces
        as %20); else it returns NULL with a message (pythonfmu would call a NULL class);
      - once an instance was made, a call after the interpreter was finalized (exit handlers,
        C++ static destructors: OMSimulator frees its FMUs so) reaches no Python: every call
        answers fmi2Error, fmi2Instantiate NULL, with no message (a Python host's logger is
        Python), and fmi2FreeInstance releases this layer's part only (the slave went with
        the interpreter).

   Everything else is pythonfmu's, fmi2Fatal after a Python exception included (robofmu's
   slave lets none reach it: it fails calls through point 1). Only the fast path (point 4)
   and the runtime (point 5) use Python's API, resolved at run time. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <elf.h>
#include <errno.h>
#include <fcntl.h>
#include <link.h>
#include <math.h>
#include <pthread.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>
#include <wchar.h>

#define EXPORT __attribute__((visibility("default")))

#include "fmi2_forward.h"       /* the FMI 2.0 types and FORWARDED_FUNCTIONS, pythonfmu's library's */
/* What this library shares with the Python side (STOCK_LIBRARY, STATUS_CATEGORY, FastShared,
   FAST_*, RUNTIME_RECORD, NOT_UTF8, MARKER, PyObject, ...): generated by robofmu build from
   robofmu.components.fmi.contract, their one definition, into the compile's include path. */
#include "robofmu_contract.h"

static struct {
#define FIELD(ret, name, params) ret (*name) params;
    FORWARDED_FUNCTIONS(FIELD)
#undef FIELD
} stock;

static void* stock_handle = NULL;        /* loaded by the first fmi2Instantiate */

/* -- pythonfmu's state at process exit (point 3 of the header comment) ------------------------ */
extern int __cxa_atexit(void (*function)(void*), void* argument, void* dso_handle);

/* In the ELF file image (data, size) of a library loaded with load bias `bias`: the address of
   its __dso_handle (a local symbol, in the symbol table only), or NULL. Checked as crtbeginS.o
   defines it in a shared library: in a writable loaded segment, holding its own address. */
static void* find_dso_handle(const unsigned char* data, size_t size, ElfW(Addr) bias)
{
#define INSIDE(offset, length) ((offset) <= size && (length) <= size - (offset))
    const Elf64_Ehdr* eh = (const Elf64_Ehdr*)data;
    if (size < sizeof *eh || memcmp(eh->e_ident, ELFMAG, SELFMAG) != 0
        || eh->e_ident[EI_CLASS] != ELFCLASS64 || eh->e_ident[EI_DATA] != ELFDATA2LSB
        || eh->e_shentsize != sizeof(Elf64_Shdr) || eh->e_phentsize != sizeof(Elf64_Phdr)
        || !INSIDE(eh->e_shoff, (size_t)eh->e_shnum * sizeof(Elf64_Shdr))
        || !INSIDE(eh->e_phoff, (size_t)eh->e_phnum * sizeof(Elf64_Phdr)))
        return NULL;
    const Elf64_Shdr* sections = (const Elf64_Shdr*)(data + eh->e_shoff);
    const Elf64_Phdr* segments = (const Elf64_Phdr*)(data + eh->e_phoff);
    static const char name[] = "__dso_handle";
    for (size_t k = 0; k < eh->e_shnum; ++k) {
        const Elf64_Shdr* table = &sections[k];
        if (table->sh_type != SHT_SYMTAB || table->sh_entsize != sizeof(Elf64_Sym)
            || table->sh_link >= eh->e_shnum || !INSIDE(table->sh_offset, table->sh_size))
            continue;
        const Elf64_Shdr* names = &sections[table->sh_link];
        if (!INSIDE(names->sh_offset, names->sh_size)) continue;
        const Elf64_Sym* symbols = (const Elf64_Sym*)(data + table->sh_offset);
        for (size_t j = 0; j < table->sh_size / sizeof(Elf64_Sym); ++j) {
            const Elf64_Sym* sym = &symbols[j];
            if (ELF64_ST_TYPE(sym->st_info) != STT_OBJECT || sym->st_shndx == SHN_UNDEF
                || sym->st_name >= names->sh_size || names->sh_size - sym->st_name < sizeof name
                || memcmp(data + names->sh_offset + sym->st_name, name, sizeof name) != 0)
                continue;
            for (size_t m = 0; m < eh->e_phnum; ++m) {
                const Elf64_Phdr* seg = &segments[m];
                if (seg->p_type == PT_LOAD && (seg->p_flags & PF_W) && sym->st_value >= seg->p_vaddr
                    && sym->st_value + sizeof(void*) <= seg->p_vaddr + seg->p_memsz) {
                    void* where = (void*)(bias + sym->st_value);
                    return *(void* const*)where == where ? where : NULL;
                }
            }
            return NULL;
        }
    }
    return NULL;
#undef INSIDE
}

/* Have pythonfmu's finalizePythonInterpreter, of its library just loaded from path as handle,
   called by exit() before that library's C++ destructors, or as the library unloads. */
static void guard_stock_exit(void* handle, const char* path)
{
    void (*finalize)(void*);   /* it is void (void): see below */
    *(void**)(&finalize) = dlsym(handle, "finalizePythonInterpreter");
    struct link_map* map = NULL;
    if (finalize == NULL || dlinfo(handle, RTLD_DI_LINKMAP, &map) != 0 || map == NULL) return;
    int fd = open(path, O_RDONLY | O_CLOEXEC);
    if (fd < 0) return;
    struct stat st;
    void* data = MAP_FAILED;
    if (fstat(fd, &st) == 0 && st.st_size > 0)
        data = mmap(NULL, (size_t)st.st_size, PROT_READ, MAP_PRIVATE, fd, 0);
    close(fd);
    if (data == MAP_FAILED) return;
    void* dso = find_dso_handle(data, (size_t)st.st_size, map->l_addr);
    munmap(data, (size_t)st.st_size);
    /* Registered with pythonfmu's library as its owner: exit() runs it (the handlers in reverse
       order of registration: before that library's C++ destructors, registered as it loaded);
       so does that library's own unloading (__cxa_finalize), after its unload hook, and then
       forgets it. Never run from this library, which may unload first. The function takes no
       argument: called with one, which the x86-64 calling convention lets it ignore. */
    if (dso != NULL) __cxa_atexit(finalize, NULL, dso);
}

/* pythonfmu's library, from the folder of this one: 1, or 0 with the reason in `error`. Its
   Python symbols must be in the process already (ensure_runtime). */
static int load_stock(char* error, size_t size)
{
    char path[4096];
    void* handle = load_beside((const void*)&load_stock, STOCK_LIBRARY, path, sizeof path, error, size);
    if (handle == NULL) return 0;
#define RESOLVE(ret, name, params) RESOLVE_BESIDE(stock, name)
    FORWARDED_FUNCTIONS(RESOLVE)
#undef RESOLVE
    guard_stock_exit(handle, path);
    stock_handle = handle;
    return 1;
}

__attribute__((destructor)) static void unload_stock(void)
{
    if (stock_handle != NULL) {
        dlclose(stock_handle);      /* pythonfmu's own unload hook runs, as without this layer */
        stock_handle = NULL;
    }
}

/* -- Python's C API, for the fast path (point 4 of the header comment) ------------------------- */
/* Resolved at the first registration, as pythonfmu's library binds to it (dlsym(RTLD_DEFAULT):
   the interpreter of a Python host, or the libpython a host that is not Python preloads). No
   Python header: objects are opaque here, only passed back to Python (PyObject: the contract
   header's). */
typedef int PyGILState;                     /* PyGILState_STATE, an enum */

#define PYTHON_FUNCTIONS(X) \
    X(PyGILState, PyGILState_Ensure, (void)) \
    X(void, PyGILState_Release, (PyGILState)) \
    X(PyObject*, PyObject_CallNoArgs, (PyObject*)) \
    X(PyObject*, PyObject_Vectorcall, (PyObject*, PyObject* const*, size_t, PyObject*)) \
    X(PyObject*, PyFloat_FromDouble, (double)) \
    X(long, PyLong_AsLong, (PyObject*)) \
    X(PyObject*, PyErr_Occurred, (void)) \
    X(void, PyErr_Clear, (void)) \
    X(int, PyContext_Enter, (PyObject*)) \
    X(int, PyContext_Exit, (PyObject*)) \
    X(void, Py_IncRef, (PyObject*)) \
    X(void, Py_DecRef, (PyObject*))

static struct {
#define FIELD(ret, name, params) ret (*name) params;
    PYTHON_FUNCTIONS(FIELD)
#undef FIELD
} py;

static int py_resolved = 0;                 /* 0: not yet; 1: all found; -1: one is missing */

static int python_api(void)
{
    int state = __atomic_load_n(&py_resolved, __ATOMIC_ACQUIRE);
    if (state != 0) return state > 0;
#define RESOLVE_PY(ret, name, params)                                                         \
    *(void**)(&py.name) = dlsym(RTLD_DEFAULT, #name);                                         \
    if (py.name == NULL) {                                                                    \
        __atomic_store_n(&py_resolved, -1, __ATOMIC_RELEASE);                                 \
        return 0;                                                                             \
    }
    PYTHON_FUNCTIONS(RESOLVE_PY)
#undef RESOLVE_PY
    __atomic_store_n(&py_resolved, 1, __ATOMIC_RELEASE);
    return 1;
}

/* What robofmu's slave shares with this layer: FastShared, FAST_VERSION, the bits FAST_OK,
   FAST_MESSAGES and FAST_CHECK that refresh(), step() and nonfinite() return, the calls
   FAST_GET_REAL and FAST_GET_BOOLEAN of FastShared.call (robofmu_contract.h). */
typedef struct {
    FastShared* shared;                     /* NULL: not registered, every call forwards */
    PyObject* refresh;                      /* new references */
    PyObject* step;
    PyObject* nonfinite;
    PyObject* quiet;                        /* NULL, or the slave's context: NumPy's errors ignored */
} Fast;

#define FAST_NONE {NULL, NULL, NULL, NULL, NULL}

/* The registration slot of the fmi2Instantiate (or fmi2Reset) under way in this thread. */
static __thread Fast* registering = NULL;

/* Runs `call` (pythonfmu's fmi2Instantiate or fmi2Reset: it constructs the slave, which
   registers) with this thread's registration slot at `slot`, then restores the slot. */
#define WHILE_REGISTERING(slot, call)                                                         \
    do {                                                                                      \
        Fast* outer_ = registering;                                                           \
        registering = &(slot);                                                                \
        call;                                                                                 \
        registering = outer_;                                                                 \
    } while (0)

/* Called by robofmu's slave at the end of its construction (ctypes); 1 if registered.
   quiet: NULL, or a context (contextvars.Context) whose NumPy error state is "ignore", entered
   around every call of refresh(), step() and nonfinite() (PyContext_Enter, then _Exit). */
EXPORT int robofmu_fast_register(FastShared* shared, PyObject* refresh, PyObject* step,
                                 PyObject* nonfinite, PyObject* quiet)
{
    Fast* slot = registering;
    if (slot == NULL || slot->shared != NULL || shared == NULL || refresh == NULL || step == NULL
        || nonfinite == NULL)
        return 0;
    if (shared->version != FAST_VERSION || shared->size != sizeof *shared
        || (shared->n > 0 && (shared->values == NULL || shared->get_real == NULL
                              || shared->get_boolean == NULL || shared->set_real == NULL
                              || shared->output == NULL || shared->saved == NULL)))
        return 0;
    const char* setting = getenv(FAST_PATH_SWITCH);
    if (setting != NULL && strcmp(setting, "0") == 0) return 0;
    if (!python_api()) return 0;
    PyGILState gil = py.PyGILState_Ensure();
    py.Py_IncRef(refresh);
    py.Py_IncRef(step);
    py.Py_IncRef(nonfinite);
    if (quiet != NULL) py.Py_IncRef(quiet);
    py.PyGILState_Release(gil);
    slot->shared = shared;
    slot->refresh = refresh;
    slot->step = step;
    slot->nonfinite = nonfinite;
    slot->quiet = quiet;
    return 1;
}

static void fast_release(Fast* fast)
{
    if (fast->shared == NULL) return;
    PyGILState gil = py.PyGILState_Ensure();
    py.Py_DecRef(fast->refresh);
    py.Py_DecRef(fast->step);
    py.Py_DecRef(fast->nonfinite);
    if (fast->quiet != NULL) py.Py_DecRef(fast->quiet);
    py.PyGILState_Release(gil);
    *fast = (Fast)FAST_NONE;
}

/* -- one instance ---------------------------------------------------------------------------- */
typedef struct {
    fmi2CallbackFunctions inner;            /* handed to pythonfmu: its logger is filter() */
    const fmi2CallbackFunctions* outer;     /* the importer's (kept alive by it, as FMI requires) */
    fmi2Component stock;                    /* pythonfmu's instance */
    int logging_on;
    size_t n_categories;
    char** categories;
    fmi2Status requested;                   /* the worst status requested during the current call */
    char* name;                             /* the instance name, for this layer's own messages */
    Fast fast;                              /* the slave's registration (point 4) */
    unsigned long long fast_calls;          /* calls the fast path served */
    int fast_stepped;                       /* a step went the fast path: the two below answer */
    double last_successful_time;            /* pythonfmu's fmi2LastSuccessfulTime, kept as it does */
    int wants_to_terminate;                 /* pythonfmu's fmi2Terminated, kept as it does */
} Instance;

static const char* category_of_status(fmi2Status s)
{
    switch (s) {
        case fmi2Warning: return "logStatusWarning";
        case fmi2Discard: return "logStatusDiscard";
        case fmi2Error: return "logStatusError";
        case fmi2Fatal: return "logStatusFatal";
        default: return "logAll";
    }
}

/* The importer's logger takes the message as a format: pass it with every '%' doubled. */
static void emit(const fmi2CallbackFunctions* to, fmi2String name, fmi2Status status,
                 fmi2String category, fmi2String message)
{
    if (to == NULL || to->logger == NULL) return;
    if (message == NULL) message = "";
    size_t percents = 0, length = 0;
    for (const char* p = message; *p; ++p, ++length) percents += (*p == '%');
    if (percents == 0) {
        to->logger(to->componentEnvironment, name, status, category, message);
        return;
    }
    char* escaped = malloc(length + percents + 1);
    if (escaped == NULL) {
        to->logger(to->componentEnvironment, name, status, category, "(message lost: out of memory)");
        return;
    }
    char* q = escaped;
    for (const char* p = message; *p; ++p) {
        *q++ = *p;
        if (*p == '%') *q++ = '%';
    }
    *q = '\0';
    to->logger(to->componentEnvironment, name, status, category, escaped);
    free(escaped);
}

static int debug_enabled(const Instance* in, fmi2String category)
{
    if (!in->logging_on) return 0;
    if (in->n_categories == 0) return 1;
    for (size_t k = 0; k < in->n_categories; ++k) {
        if (strcmp(in->categories[k], "logAll") == 0) return 1;
        if (category != NULL && strcmp(in->categories[k], category) == 0) return 1;
    }
    return 0;
}

/* pythonfmu's logger (it logs everything: it was instantiated with loggingOn = true). */
static void filter(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...)
{
    Instance* in = (Instance*)env;
    if (in == NULL) return;
    if (category != NULL && strcmp(category, STATUS_CATEGORY) == 0) {
        if (status > in->requested) in->requested = status;
        category = category_of_status(status);
    }
    if (status != fmi2OK || debug_enabled(in, category)) {
        emit(in->outer, name, status, category, message);
    }
}

static void free_categories(Instance* in)
{
    for (size_t k = 0; k < in->n_categories; ++k) free(in->categories[k]);
    free(in->categories);
    in->categories = NULL;
    in->n_categories = 0;
}

static fmi2Status finish(const Instance* in, fmi2Status s)
{
    return s > in->requested ? s : in->requested;
}

#define ENTER(c)                                              \
    Instance* in = (Instance*)(c);                            \
    if (in == NULL || python_gone()) return fmi2Error;        \
    in->requested = fmi2OK

/* -- the fast path (point 4 of the header comment) ------------------------------------------- */
static int fast_on(const Instance* in)
{
    return in->fast.shared != NULL && in->fast.shared->active;
}

/* Whether every value reference names a slot of `mask`. */
static int fast_all(const FastShared* shared, const unsigned char* mask, const fmi2ValueReference vr[],
                    size_t nvr)
{
    if (nvr > 0 && vr == NULL) return 0;
    for (size_t k = 0; k < nvr; ++k) {
        if (vr[k] >= shared->n || !mask[vr[k]]) return 0;
    }
    return 1;
}

/* A Python call's result (a new reference or NULL), with the GIL held: FAST_OK,
   FAST_MESSAGES and FAST_CHECK bits, or -1 if it raised (cleared: the slave's callables catch everything, so
   this is a bug) or returned no int. */
static int fast_result(PyObject* result)
{
    long bits = -1;
    if (result != NULL) {
        bits = py.PyLong_AsLong(result);
        py.Py_DecRef(result);
    }
    if (result == NULL || (bits == -1 && py.PyErr_Occurred() != NULL)) {
        py.PyErr_Clear();
        return -1;
    }
    return (int)(bits & (FAST_OK | FAST_MESSAGES | FAST_CHECK));
}

/* After a fast-path Python call (the GIL released): the messages the slave queued reach the
   importer through pythonfmu, during this call (its fmi2GetString of nothing reads the slave's
   log queue into filter()). 1 if the call succeeded. */
static int fast_done(Instance* in, int bits, const char* call)
{
    if (bits < 0) {
        char text[512];
        snprintf(text, sizeof text, "%.200s: %s failed: robofmu's slave raised an exception in the FMI "
                 "fast path (robofmu_fmi2.c)", in->name ? in->name : "", call);
        filter(in, in->name, fmi2Error, STATUS_CATEGORY, text);
    }
    if (bits < 0 || (bits & FAST_MESSAGES)) {
        fmi2Status s = stock.fmi2GetString(in->stock, NULL, 0, NULL);
        if (s > in->requested) in->requested = s;
    }
    return bits > 0 && (bits & FAST_OK);
}

/* NumPy's floating-point errors ignored around a call into the slave (what its
   components/fmi/quiet.py does): the slave's own context entered, no allocation (setting the
   error state in the caller's context makes a new mapping and a token every time). 1 if the
   call may go ahead (entered, or no context: the slave quiets its calls itself); 0 if the
   context could not be entered (already entered: a call into this instance from its own
   Python code), the reason logged. */
static int quiet_begin(Instance* in, const char* call)
{
    if (in->fast.quiet == NULL || py.PyContext_Enter(in->fast.quiet) == 0) return 1;
    py.PyErr_Clear();
    char text[512];
    snprintf(text, sizeof text, "%.200s: %s refused: the instance's Python context is already entered "
             "(a call into this instance during one of its own calls?)", in->name ? in->name : "", call);
    filter(in, in->name, fmi2Error, STATUS_CATEGORY, text);
    return 0;
}

static void quiet_end(const Fast* fast)
{
    if (fast->quiet != NULL && py.PyContext_Exit(fast->quiet) != 0) py.PyErr_Clear();
}

/* step(t, h) (a new reference or NULL), with the GIL held. */
static PyObject* fast_step(PyObject* step, double t, double h)
{
    PyObject* args[2] = {py.PyFloat_FromDouble(t), py.PyFloat_FromDouble(h)};
    PyObject* result = NULL;
    if (args[0] != NULL && args[1] != NULL) result = py.PyObject_Vectorcall(step, args, 2, NULL);
    if (args[0] != NULL) py.Py_DecRef(args[0]);
    if (args[1] != NULL) py.Py_DecRef(args[1]);
    return result;
}

static int outputs_finite(const FastShared* shared)
{
    double sum = 0.0;                       /* nan and inf propagate through the sum */
    for (size_t k = 0; k < shared->n; ++k) {
        if (shared->output[k]) sum += shared->values[k];
    }
    if (isfinite(sum)) return 1;
    for (size_t k = 0; k < shared->n; ++k) {    /* an overflow of finite values is no failure */
        if (shared->output[k] && !isfinite(shared->values[k])) return 0;
    }
    return 1;
}

/* The outputs as saved before a step that computed non-finite ones. */
static void restore_outputs(FastShared* shared)
{
    for (size_t k = 0; k < shared->n; ++k) {
        if (shared->output[k]) shared->values[k] = shared->saved[k];
    }
}

/* Outputs up to date before they are read: 1, or 0 if refresh() failed (read zeros).
   The values are saved first; if refresh() says FAST_CHECK (it computed the outputs and left
   the check to this layer) and an output is not finite, nonfinite() holds the saved ones and
   reports; else the outputs are current. */
static int fast_refresh(Instance* in, int call)
{
    FastShared* shared = in->fast.shared;
    if (!shared->dirty) return 1;
    shared->call = call;
    memcpy(shared->saved, shared->values, shared->n * sizeof *shared->values);
    const char* name = call == FAST_GET_REAL ? "fmi2GetReal" : "fmi2GetBoolean";
    PyGILState gil = py.PyGILState_Ensure();
    int bits = 0;
    if (quiet_begin(in, name)) {
        bits = fast_result(py.PyObject_CallNoArgs(in->fast.refresh));
        if (bits > 0 && (bits & FAST_CHECK)) {
            if (outputs_finite(shared)) {
                shared->dirty = 0;
            } else {
                int more = fast_result(py.PyObject_CallNoArgs(in->fast.nonfinite));
                bits = more < 0 ? more : (more | (bits & FAST_MESSAGES));
            }
        }
        quiet_end(&in->fast);
    }
    py.PyGILState_Release(gil);
    return fast_done(in, bits, name);
}

/* pythonfmu's fmi2DoStep keeps these from the slave's answer: kept here for every step. */
static void note_step(Instance* in, fmi2Status stock_status, fmi2Real t, fmi2Real h)
{
    if (stock_status == fmi2OK) {
        in->last_successful_time = t + h;
    } else if (stock_status == fmi2Discard) {
        in->last_successful_time = t;
        in->wants_to_terminate = 1;
    }
}

/* The marker of this library: a FMU's binary is robofmu's, not pythonfmu's (tests, doctor). */
EXPORT const char* robofmu_fmi_library(void)
{
    return MARKER;
}

/* Whether instance c is served by the fast path (its slave registered). */
EXPORT int robofmu_fast_path(fmi2Component c)
{
    return c != NULL && ((Instance*)c)->fast.shared != NULL;
}

/* How many FMI calls of instance c the fast path served. */
EXPORT unsigned long long robofmu_fast_calls(fmi2Component c)
{
    return c != NULL ? ((Instance*)c)->fast_calls : 0;
}

/* -- the resource folder and the Python runtime (points 5 and 6 of the header comment) ----- */
static pthread_mutex_t load_lock = PTHREAD_MUTEX_INITIALIZER;
static int (*py_is_initialized)(void) = NULL;   /* Py_IsInitialized, once a runtime is in the process */
static int python_seen = 0;                     /* an instance was made: Python was initialized */

/* Whether the interpreter the instances live in has been finalized (process exit, static
   destructors): then no call may reach pythonfmu, whose every call enters Python. */
static int python_gone(void)
{
    return __atomic_load_n(&python_seen, __ATOMIC_ACQUIRE) && py_is_initialized != NULL
        && !py_is_initialized();
}

static int hex_digit(char c)
{
    if (c >= '0' && c <= '9') return c - '0';
    if (c >= 'a' && c <= 'f') return c - 'a' + 10;
    if (c >= 'A' && c <= 'F') return c - 'A' + 10;
    return -1;
}

/* fmuResourceLocation (file:///path, file:/path, file://localhost/path, percent-encoded) as
   a folder path that exists and holds pythonfmu's resources/slavemodule.txt: 1, else 0 with
   the reason. */
static int resource_folder(fmi2String uri, char* path, size_t size, char* error, size_t error_size)
{
    if (uri == NULL || uri[0] == '\0') {
        snprintf(error, error_size, "fmuResourceLocation is %s", uri == NULL ? "NULL" : "empty");
        return 0;
    }
    const char* p = uri;
    if (strncmp(p, "file://localhost/", 17) == 0) {
        p += 16;
    } else if (strncmp(p, "file:///", 8) == 0) {
        p += 7;
    } else if (strncmp(p, "file:/", 6) == 0 && p[6] != '/') {
        p += 5;
    } else {
        snprintf(error, error_size, "fmuResourceLocation \"%.4000s\" is not a file URI of this machine "
                 "(file:///absolute/path)", uri);
        return 0;
    }
    size_t n = 0;
    for (; *p != '\0'; ++p) {
        char c = *p;
        if (c == '%' && hex_digit(p[1]) >= 0 && hex_digit(p[2]) >= 0) {
            c = (char)(hex_digit(p[1]) * 16 + hex_digit(p[2]));
            p += 2;
        }
        if (n + 1 >= size || c == '\0') {
            snprintf(error, error_size, "fmuResourceLocation \"%.4000s\" is too long or holds %%00", uri);
            return 0;
        }
        path[n++] = c;
    }
    while (n > 1 && path[n - 1] == '/') --n;
    path[n] = '\0';
    char module[sizeof "/slavemodule.txt" + 4096];
    struct stat st;
    if (stat(path, &st) != 0 || !S_ISDIR(st.st_mode) || access(path, R_OK | X_OK) != 0) {
        snprintf(error, error_size, "%.4000s (from fmuResourceLocation \"%.2000s\") %s", path, uri,
                 stat(path, &st) != 0 ? "does not exist" : !S_ISDIR(st.st_mode) ? "is not a folder"
                                                          : "cannot be read");
        return 0;
    }
    snprintf(module, sizeof module, "%.4000s/slavemodule.txt", path);
    if (access(module, R_OK) != 0) {
        snprintf(error, error_size, "%.4000s cannot be read (%s): the resource folder is not this FMU's "
                 "(fmuResourceLocation \"%.2000s\")", module, strerror(errno), uri);
        return 0;
    }
    return 1;
}

/* The folder as pythonfmu takes it: "file://" and the path, with only spaces encoded. */
static void stock_uri(const char* path, char* uri, size_t size)
{
    size_t n = (size_t)snprintf(uri, size, "file://");
    for (const char* p = path; *p != '\0' && n + 4 < size; ++p) {
        if (*p == ' ') {
            memcpy(uri + n, "%20", 3);
            n += 3;
        } else {
            uri[n++] = *p;
        }
    }
    uri[n] = '\0';
}

typedef struct {
    char version[64];           /* "3.11" */
    char program[4096];         /* the interpreter the FMU was built with (a venv's bin/python) */
    char library[4096];         /* its libpython, full path; empty: built without one */
} Runtime;

static void copy_value(char* to, size_t size, const char* value)
{
    snprintf(to, size, "%s", value);
}

/* resources/robofmu_python.txt (key=value lines, written by robofmu build), then the
   environment's ROBOFMU_PYTHON and ROBOFMU_LIBPYTHON over it. 1 if the record was read. */
static int read_runtime(const char* resources, Runtime* rt)
{
    memset(rt, 0, sizeof *rt);
    char path[4096 + sizeof RUNTIME_RECORD + 2];
    snprintf(path, sizeof path, "%.4096s/%s", resources, RUNTIME_RECORD);
    FILE* f = fopen(path, "r");
    if (f != NULL) {
        char line[8192];
        while (fgets(line, sizeof line, f) != NULL) {
            line[strcspn(line, "\r\n")] = '\0';
            char* eq = strchr(line, '=');
            if (line[0] == '#' || eq == NULL) continue;
            *eq = '\0';
            if (strcmp(line, "version") == 0) copy_value(rt->version, sizeof rt->version, eq + 1);
            else if (strcmp(line, "program") == 0) copy_value(rt->program, sizeof rt->program, eq + 1);
            else if (strcmp(line, "library") == 0) copy_value(rt->library, sizeof rt->library, eq + 1);
        }
        fclose(f);
    }
    const char* program = getenv("ROBOFMU_PYTHON");
    const char* library = getenv("ROBOFMU_LIBPYTHON");
    if (program != NULL && program[0] != '\0') copy_value(rt->program, sizeof rt->program, program);
    if (library != NULL && library[0] != '\0') copy_value(rt->library, sizeof rt->library, library);
    return f != NULL;
}

#define DOCTOR "run `robofmu doctor --fmus FOLDER` with the robofmu that built the FMU, or set " \
               "ROBOFMU_LIBPYTHON (a libpython shared library) and ROBOFMU_PYTHON (the python program " \
               "of an environment with the FMU's resources/requirements.txt)"

/* A Python runtime in the process, of the version the FMU was built for, told which program it
   is if it is not running yet: 1, or 0 with the reason. Called with load_lock held. */
static int ensure_runtime(const char* resources, char* error, size_t size)
{
    Runtime rt;
    int recorded = read_runtime(resources, &rt);
    void* is_initialized = dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (is_initialized == NULL) {                       /* a host that is not Python: load it */
        if (rt.library[0] == '\0') {
            snprintf(error, size, "no Python in this process and %s; %s",
                     recorded ? "the FMU records no libpython (its Python was built without one)"
                              : "no " RUNTIME_RECORD " in the FMU's resources to say which", DOCTOR);
            return 0;
        }
        void* library = dlopen(rt.library, RTLD_NOW | RTLD_GLOBAL);
        if (library == NULL) {
            const char* why = dlerror();
            snprintf(error, size, "cannot load the Python runtime %.2000s: %.2000s; %s", rt.library,
                     why ? why : "unknown error", DOCTOR);
            return 0;
        }
        is_initialized = dlsym(library, "Py_IsInitialized");
        if (is_initialized == NULL) {
            snprintf(error, size, "%.4000s is not a Python runtime (no Py_IsInitialized); %s", rt.library, DOCTOR);
            return 0;
        }
    }
    *(void**)(&py_is_initialized) = is_initialized;
    const char* (*get_version)(void);
    *(void**)(&get_version) = dlsym(RTLD_DEFAULT, "Py_GetVersion");
    if (rt.version[0] != '\0' && get_version != NULL) {
        const char* running = get_version();
        size_t n = strlen(rt.version);
        if (running == NULL || strncmp(running, rt.version, n) != 0 || (running[n] != '.' && running[n] != ' ')) {
            if (running == NULL) running = "?";
            snprintf(error, size, "this process runs Python %.*s, the FMU was built for Python %s "
                     "(pythonfmu's library is compiled for one Python version); %s",
                     (int)strcspn(running, " "), running, rt.version, DOCTOR);
            return 0;
        }
    }
    if (!py_is_initialized() && rt.program[0] != '\0') {
        /* pythonfmu starts the interpreter: it finds its standard library and packages from
           the program it is told it is (a venv's python: that venv), not from PATH. */
        if (access(rt.program, X_OK) != 0) {
            snprintf(error, size, "the Python program %.4000s is not there (%s); %s", rt.program,
                     strerror(errno), DOCTOR);
            return 0;
        }
        wchar_t* (*decode)(const char*, size_t*);
        void (*set_program_name)(const wchar_t*);
        *(void**)(&decode) = dlsym(RTLD_DEFAULT, "Py_DecodeLocale");
        *(void**)(&set_program_name) = dlsym(RTLD_DEFAULT, "Py_SetProgramName");
        static wchar_t* program = NULL;                 /* Python keeps the pointer */
        if (decode != NULL && set_program_name != NULL && program == NULL) {
            program = decode(rt.program, NULL);
            if (program != NULL) set_program_name(program);
        }
    }
    return 1;
}

/* -- FMI 2.0 functions ----------------------------------------------------------------------- */
EXPORT const char* fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char* fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn)
{
    if (functions == NULL || python_gone()) return NULL;    /* nothing to log with, or no Python */
    char resources[4096], error[8192];
    const char* refused = NULL;
    if (!resource_folder(fmuResourceLocation, resources, sizeof resources, error, sizeof error)) {
        refused = "the FMU's resource folder";
    } else {
        pthread_mutex_lock(&load_lock);
        if (!ensure_runtime(resources, error, sizeof error)) {
            refused = "the Python runtime";
        } else if (stock_handle == NULL && !load_stock(error, sizeof error)) {
            refused = "pythonfmu's export library";
        }
        pthread_mutex_unlock(&load_lock);
    }
    if (refused != NULL) {
        char text[sizeof error + 256];
        snprintf(text, sizeof text, "fmi2Instantiate: cannot instantiate, %s: %s", refused, error);
        emit(functions, instanceName, fmi2Error, category_of_status(fmi2Error), text);
        return NULL;
    }
    char uri[sizeof resources * 3 + 16];
    stock_uri(resources, uri, sizeof uri);
    Instance* in = calloc(1, sizeof *in);
    if (in == NULL) return NULL;
    in->outer = functions;
    in->inner = *functions;
    in->inner.logger = filter;
    in->inner.componentEnvironment = in;
    in->logging_on = loggingOn ? 1 : 0;
    in->name = strdup(instanceName ? instanceName : "");
    in->last_successful_time = NAN;     /* pythonfmu's start values */
    Fast pending = FAST_NONE;
    WHILE_REGISTERING(pending, in->stock = stock.fmi2Instantiate(instanceName, fmuType, fmuGUID, uri,
                                                                 &in->inner, visible, fmi2True));
    if (in->stock == NULL) {            /* pythonfmu has logged why (fmi2Fatal: always shown) */
        fast_release(&pending);
        free(in->name);
        free(in);
        return NULL;
    }
    __atomic_store_n(&python_seen, 1, __ATOMIC_RELEASE);
    in->fast = pending;
    return in;
}

EXPORT void fmi2FreeInstance(fmi2Component c)
{
    Instance* in = (Instance*)c;
    if (in == NULL) return;
    if (!python_gone()) {               /* else its Python objects went with the interpreter */
        fast_release(&in->fast);        /* before pythonfmu releases the slave */
        stock.fmi2FreeInstance(in->stock);
    }
    free_categories(in);
    free(in->name);
    free(in);
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                      const fmi2String categories[])
{
    Instance* in = (Instance*)c;
    if (in == NULL) return fmi2Error;
    free_categories(in);
    in->logging_on = loggingOn ? 1 : 0;
    if (nCategories > 0 && categories != NULL) {
        in->categories = calloc(nCategories, sizeof *in->categories);
        if (in->categories == NULL) return fmi2Error;
        for (size_t k = 0; k < nCategories; ++k) {
            in->categories[in->n_categories] = strdup(categories[k] ? categories[k] : "");
            if (in->categories[in->n_categories] != NULL) in->n_categories++;
        }
    }
    return fmi2OK;
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                                      fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    ENTER(c);
    return finish(in, stock.fmi2SetupExperiment(in->stock, toleranceDefined, tolerance, startTime,
                                                stopTimeDefined, stopTime));
}

#define FORWARD0(name)                                                                        \
    EXPORT fmi2Status name(fmi2Component c)                                                   \
    {                                                                                         \
        ENTER(c);                                                                      \
        return finish(in, stock.name(in->stock));                                             \
    }
FORWARD0(fmi2EnterInitializationMode)
FORWARD0(fmi2ExitInitializationMode)
FORWARD0(fmi2Terminate)
FORWARD0(fmi2CancelStep)

/* pythonfmu constructs the slave anew: it registers anew. */
EXPORT fmi2Status fmi2Reset(fmi2Component c)
{
    ENTER(c);
    fast_release(&in->fast);
    Fast pending = FAST_NONE;
    fmi2Status s;
    WHILE_REGISTERING(pending, s = stock.fmi2Reset(in->stock));
    in->fast = pending;
    return finish(in, s);
}

#define FORWARD_VALUES(name, type)                                                            \
    EXPORT fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, type value[]) \
    {                                                                                         \
        ENTER(c);                                                                      \
        return finish(in, stock.name(in->stock, vr, nvr, value));                             \
    }
FORWARD_VALUES(fmi2GetInteger, fmi2Integer)
FORWARD_VALUES(fmi2GetString, fmi2String)
FORWARD_VALUES(fmi2SetInteger, const fmi2Integer)
FORWARD_VALUES(fmi2SetBoolean, const fmi2Boolean)

/* Whether text is well-formed UTF-8, by the rules of CPython's strict decoder (Unicode 3-7). */
static int utf8_valid(const unsigned char* p)
{
    while (*p) {
        unsigned char c = *p;
        int n;
        unsigned char low = 0x80, high = 0xBF;
        if (c < 0x80) { ++p; continue; }
        else if (c >= 0xC2 && c <= 0xDF) n = 1;
        else if (c == 0xE0) { n = 2; low = 0xA0; }
        else if (c >= 0xE1 && c <= 0xEC) n = 2;
        else if (c == 0xED) { n = 2; high = 0x9F; }
        else if (c >= 0xEE && c <= 0xEF) n = 2;
        else if (c == 0xF0) { n = 3; low = 0x90; }
        else if (c >= 0xF1 && c <= 0xF3) n = 3;
        else if (c == 0xF4) { n = 3; high = 0x8F; }
        else return 0;
        if (p[1] < low || p[1] > high) return 0;
        for (int k = 2; k <= n; ++k) {
            if (p[k] < 0x80 || p[k] > 0xBF) return 0;
        }
        p += n + 1;
    }
    return 1;
}

/* pythonfmu's fmi2SetString decodes each value strictly as UTF-8 and, on bytes that are not,
   calls the slave with NULL: fmi2Fatal and a damaged instance. So a value that is not UTF-8
   goes to the slave as NOT_UTF8 (robofmu_contract.h) and the hex of its bytes, which the
   slave refuses naming the parameter. */

EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[])
{
    ENTER(c);
    if (nvr > 0 && (vr == NULL || value == NULL)) {
        char text[512];
        snprintf(text, sizeof text, "%.200s: fmi2SetString: no value reference or value array for %zu "
                 "variables; nothing set", in->name, nvr);
        filter(in, in->name, fmi2Error, STATUS_CATEGORY, text);
        return finish(in, fmi2OK);
    }
    size_t invalid = 0;
    for (size_t k = 0; k < nvr; ++k) invalid += value[k] != NULL && !utf8_valid((const unsigned char*)value[k]);
    if (invalid == 0) return finish(in, stock.fmi2SetString(in->stock, vr, nvr, value));
    fmi2String* forwarded = calloc(nvr, sizeof *forwarded);
    int ok = forwarded != NULL;
    for (size_t k = 0; ok && k < nvr; ++k) {
        forwarded[k] = value[k];
        if (value[k] == NULL || utf8_valid((const unsigned char*)value[k])) continue;
        size_t n = strlen(value[k]);
        char* hex = malloc(sizeof NOT_UTF8 + 2 * n);
        if (hex == NULL) { ok = 0; break; }
        memcpy(hex, NOT_UTF8, sizeof NOT_UTF8 - 1);
        for (size_t j = 0; j < n; ++j)
            snprintf(hex + sizeof NOT_UTF8 - 1 + 2 * j, 3, "%02x", (unsigned char)value[k][j]);
        hex[sizeof NOT_UTF8 - 1 + 2 * n] = '\0';
        forwarded[k] = hex;
    }
    fmi2Status s = fmi2OK;
    if (ok) {
        s = stock.fmi2SetString(in->stock, vr, nvr, forwarded);
    } else {
        char text[256];
        snprintf(text, sizeof text, "%.200s: fmi2SetString: out of memory; nothing set", in->name);
        filter(in, in->name, fmi2Error, STATUS_CATEGORY, text);
    }
    for (size_t k = 0; forwarded != NULL && k < nvr; ++k) {
        if (forwarded[k] != value[k]) free((void*)forwarded[k]);
    }
    free(forwarded);
    return finish(in, s);
}

EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[])
{
    ENTER(c);
    if (fast_on(in) && (value != NULL || nvr == 0) && fast_all(in->fast.shared, in->fast.shared->get_real, vr, nvr)) {
        in->fast_calls++;
        const double* values = in->fast.shared->values;
        if (fast_refresh(in, FAST_GET_REAL)) {
            for (size_t k = 0; k < nvr; ++k) value[k] = values[vr[k]];
        } else {
            for (size_t k = 0; k < nvr; ++k) value[k] = 0.0;     /* as the slave's get_real: no NaN leaves */
        }
        return finish(in, fmi2OK);
    }
    return finish(in, stock.fmi2GetReal(in->stock, vr, nvr, value));
}

EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[])
{
    ENTER(c);
    if (fast_on(in) && (value != NULL || nvr == 0) && fast_all(in->fast.shared, in->fast.shared->get_boolean, vr, nvr)) {
        in->fast_calls++;
        const double* values = in->fast.shared->values;
        int valid = fast_refresh(in, FAST_GET_BOOLEAN);
        for (size_t k = 0; k < nvr; ++k) value[k] = valid && values[vr[k]] != 0.0;
        return finish(in, fmi2OK);
    }
    return finish(in, stock.fmi2GetBoolean(in->stock, vr, nvr, value));
}

EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[])
{
    ENTER(c);
    if (fast_on(in) && (value != NULL || nvr == 0) && fast_all(in->fast.shared, in->fast.shared->set_real, vr, nvr)) {
        in->fast_calls++;
        FastShared* shared = in->fast.shared;
        int finite = 1;
        for (size_t k = 0; k < nvr; ++k) {
            shared->values[vr[k]] = value[k];
            finite &= isfinite(value[k]) != 0;
        }
        shared->dirty = 1;
        /* Inputs found finite stay so when only finite values are set: the slave checks them
           again only after a non-finite one (its own sets clear the flag too). */
        if (!finite) shared->inputs_checked = 0;
        return finish(in, fmi2OK);
    }
    return finish(in, stock.fmi2SetReal(in->stock, vr, nvr, value));
}

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* state)
{
    ENTER(c);
    return finish(in, stock.fmi2GetFMUstate(in->stock, state));
}

EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state)
{
    ENTER(c);
    return finish(in, stock.fmi2SetFMUstate(in->stock, state));
}

EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* state)
{
    ENTER(c);
    return finish(in, stock.fmi2FreeFMUstate(in->stock, state));
}

EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate state, size_t* size)
{
    ENTER(c);
    return finish(in, stock.fmi2SerializedFMUstateSize(in->stock, state, size));
}

EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate state, fmi2Byte bytes[], size_t size)
{
    ENTER(c);
    return finish(in, stock.fmi2SerializeFMUstate(in->stock, state, bytes, size));
}

EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte bytes[], size_t size,
                                          fmi2FMUstate* state)
{
    ENTER(c);
    return finish(in, stock.fmi2DeSerializeFMUstate(in->stock, bytes, size, state));
}

EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown[],
                                               size_t nUnknown, const fmi2ValueReference vKnown[],
                                               size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[])
{
    ENTER(c);
    return finish(in, stock.fmi2GetDirectionalDerivative(in->stock, vUnknown, nUnknown, vKnown, nKnown,
                                                         dvKnown, dvUnknown));
}

EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], const fmi2Real value[])
{
    ENTER(c);
    return finish(in, stock.fmi2SetRealInputDerivatives(in->stock, vr, nvr, order, value));
}

EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                               const fmi2Integer order[], fmi2Real value[])
{
    ENTER(c);
    return finish(in, stock.fmi2GetRealOutputDerivatives(in->stock, vr, nvr, order, value));
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint,
                             fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    ENTER(c);
    fmi2Status s;
    if (fast_on(in)) {
        in->fast_calls++;
        in->fast_stepped = 1;
        FastShared* shared = in->fast.shared;
        memcpy(shared->saved, shared->values, shared->n * sizeof *shared->values);
        PyGILState gil = py.PyGILState_Ensure();
        int bits = 0;
        if (quiet_begin(in, "fmi2DoStep")) {
            bits = fast_result(fast_step(in->fast.step, currentCommunicationPoint, communicationStepSize));
            quiet_end(&in->fast);
        }
        py.PyGILState_Release(gil);
        if (bits > 0 && (bits & FAST_CHECK)) {     /* outputs computed at t + h (no feedthrough) */
            if (outputs_finite(shared)) shared->dirty = 0;
            else restore_outputs(shared);          /* stale: the read computes and reports them */
        }
        s = fast_done(in, bits, "fmi2DoStep") ? fmi2OK : fmi2Discard;   /* pythonfmu's statuses */
    } else {
        s = stock.fmi2DoStep(in->stock, currentCommunicationPoint, communicationStepSize,
                             noSetFMUStatePriorToCurrentPoint);
    }
    note_step(in, s, currentCommunicationPoint, communicationStepSize);
    return finish(in, s);
}

#define FORWARD_STATUS(name, type)                                                            \
    EXPORT fmi2Status name(fmi2Component c, const fmi2StatusKind s, type* value)              \
    {                                                                                         \
        ENTER(c);                                                                      \
        return finish(in, stock.name(in->stock, s, value));                                   \
    }
FORWARD_STATUS(fmi2GetStatus, fmi2Status)
FORWARD_STATUS(fmi2GetIntegerStatus, fmi2Integer)
FORWARD_STATUS(fmi2GetStringStatus, fmi2String)

/* pythonfmu's answers, kept here once a step went the fast path (pythonfmu did not see it). */
EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real* value)
{
    ENTER(c);
    if (in->fast_stepped && s == fmi2LastSuccessfulTime && value != NULL) {
        *value = in->last_successful_time;
        return fmi2OK;
    }
    return finish(in, stock.fmi2GetRealStatus(in->stock, s, value));
}

EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean* value)
{
    ENTER(c);
    if (in->fast_stepped && s == fmi2Terminated && value != NULL) {
        *value = in->wants_to_terminate ? fmi2True : 0;
        return fmi2OK;
    }
    return finish(in, stock.fmi2GetBooleanStatus(in->stock, s, value));
}
