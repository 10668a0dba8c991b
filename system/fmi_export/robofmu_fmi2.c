/* robofmu's FMI 2.0 co-simulation export library: a thin layer in front of pythonfmu's.

   Every robofmu FMU carries, in binaries/linux64/, this library as <modelIdentifier>.so and
   pythonfmu 0.7.0's own export library, unchanged, as libpythonfmu-export.so. The importer
   loads this one; it loads pythonfmu's from its own folder and forwards every FMI function to
   it, changing two things (robofmu.system.fmi_export explains why; docs/design.md too) and
   guarding against a third (point 3):

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
      emptying the pointer, and the hook then writes into the freed block (system/libcosim.py,
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

   Everything else is pythonfmu's, fmi2Fatal after a Python exception included (robofmu's
   slave lets none reach it: it fails calls through point 1). Nothing here uses Python's API. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <elf.h>
#include <fcntl.h>
#include <link.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#define EXPORT __attribute__((visibility("default")))
#define STOCK_LIBRARY "libpythonfmu-export.so"
#define STATUS_CATEGORY "robofmu:status"

/* -- FMI 2.0 types (fmi2TypesPlatform.h, fmi2FunctionTypes.h of the standard) -------------- */
#ifdef ROBOFMU_CHECK_WITH_FMI2_HEADERS
/* Compiled against the standard's headers instead (tests/test_fmi_status.py does, with the
   copy fmpy ships), every definition below is checked against the standard's prototypes. */
#include "fmi2Functions.h"
#else
typedef void* fmi2Component;
typedef void* fmi2ComponentEnvironment;
typedef void* fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char* fmi2String;
typedef char fmi2Byte;
#define fmi2True 1

typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;

typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String instanceName, fmi2Status,
                                   fmi2String category, fmi2String message, ...);
typedef void* (*fmi2CallbackAllocateMemory)(size_t nobj, size_t size);
typedef void (*fmi2CallbackFreeMemory)(void* obj);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);

typedef struct {
    fmi2CallbackLogger logger;
    fmi2CallbackAllocateMemory allocateMemory;
    fmi2CallbackFreeMemory freeMemory;
    fmi2StepFinished stepFinished;
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;
#endif

/* -- pythonfmu's library ------------------------------------------------------------------- */
#define STOCK_FUNCTIONS(X) \
    X(fmi2Component, fmi2Instantiate, (fmi2String, fmi2Type, fmi2String, fmi2String, const fmi2CallbackFunctions*, fmi2Boolean, fmi2Boolean)) \
    X(void, fmi2FreeInstance, (fmi2Component)) \
    X(fmi2Status, fmi2SetupExperiment, (fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real)) \
    X(fmi2Status, fmi2EnterInitializationMode, (fmi2Component)) \
    X(fmi2Status, fmi2ExitInitializationMode, (fmi2Component)) \
    X(fmi2Status, fmi2Terminate, (fmi2Component)) \
    X(fmi2Status, fmi2Reset, (fmi2Component)) \
    X(fmi2Status, fmi2GetReal, (fmi2Component, const fmi2ValueReference*, size_t, fmi2Real*)) \
    X(fmi2Status, fmi2GetInteger, (fmi2Component, const fmi2ValueReference*, size_t, fmi2Integer*)) \
    X(fmi2Status, fmi2GetBoolean, (fmi2Component, const fmi2ValueReference*, size_t, fmi2Boolean*)) \
    X(fmi2Status, fmi2GetString, (fmi2Component, const fmi2ValueReference*, size_t, fmi2String*)) \
    X(fmi2Status, fmi2SetReal, (fmi2Component, const fmi2ValueReference*, size_t, const fmi2Real*)) \
    X(fmi2Status, fmi2SetInteger, (fmi2Component, const fmi2ValueReference*, size_t, const fmi2Integer*)) \
    X(fmi2Status, fmi2SetBoolean, (fmi2Component, const fmi2ValueReference*, size_t, const fmi2Boolean*)) \
    X(fmi2Status, fmi2SetString, (fmi2Component, const fmi2ValueReference*, size_t, const fmi2String*)) \
    X(fmi2Status, fmi2GetFMUstate, (fmi2Component, fmi2FMUstate*)) \
    X(fmi2Status, fmi2SetFMUstate, (fmi2Component, fmi2FMUstate)) \
    X(fmi2Status, fmi2FreeFMUstate, (fmi2Component, fmi2FMUstate*)) \
    X(fmi2Status, fmi2SerializedFMUstateSize, (fmi2Component, fmi2FMUstate, size_t*)) \
    X(fmi2Status, fmi2SerializeFMUstate, (fmi2Component, fmi2FMUstate, fmi2Byte*, size_t)) \
    X(fmi2Status, fmi2DeSerializeFMUstate, (fmi2Component, const fmi2Byte*, size_t, fmi2FMUstate*)) \
    X(fmi2Status, fmi2GetDirectionalDerivative, (fmi2Component, const fmi2ValueReference*, size_t, const fmi2ValueReference*, size_t, const fmi2Real*, fmi2Real*)) \
    X(fmi2Status, fmi2SetRealInputDerivatives, (fmi2Component, const fmi2ValueReference*, size_t, const fmi2Integer*, const fmi2Real*)) \
    X(fmi2Status, fmi2GetRealOutputDerivatives, (fmi2Component, const fmi2ValueReference*, size_t, const fmi2Integer*, fmi2Real*)) \
    X(fmi2Status, fmi2DoStep, (fmi2Component, fmi2Real, fmi2Real, fmi2Boolean)) \
    X(fmi2Status, fmi2CancelStep, (fmi2Component)) \
    X(fmi2Status, fmi2GetStatus, (fmi2Component, const fmi2StatusKind, fmi2Status*)) \
    X(fmi2Status, fmi2GetRealStatus, (fmi2Component, const fmi2StatusKind, fmi2Real*)) \
    X(fmi2Status, fmi2GetIntegerStatus, (fmi2Component, const fmi2StatusKind, fmi2Integer*)) \
    X(fmi2Status, fmi2GetBooleanStatus, (fmi2Component, const fmi2StatusKind, fmi2Boolean*)) \
    X(fmi2Status, fmi2GetStringStatus, (fmi2Component, const fmi2StatusKind, fmi2String*))

static struct {
#define FIELD(ret, name, params) ret (*name) params;
    STOCK_FUNCTIONS(FIELD)
#undef FIELD
} stock;

static void* stock_handle = NULL;
static char load_error[8192] = "not loaded";

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

__attribute__((constructor)) static void load_stock(void)
{
    Dl_info self;
    if (!dladdr((void*)&load_stock, &self) || self.dli_fname == NULL) {
        snprintf(load_error, sizeof load_error, "cannot find the folder of this library");
        return;
    }
    const char* slash = strrchr(self.dli_fname, '/');
    size_t dir = slash ? (size_t)(slash - self.dli_fname) + 1 : 0;
    char path[4096];
    if (dir + sizeof STOCK_LIBRARY > sizeof path) {
        snprintf(load_error, sizeof load_error, "the path of %.4000s is too long", self.dli_fname);
        return;
    }
    memcpy(path, self.dli_fname, dir);
    memcpy(path + dir, STOCK_LIBRARY, sizeof STOCK_LIBRARY);
    void* handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (handle == NULL) {
        const char* why = dlerror();
        snprintf(load_error, sizeof load_error, "cannot load %.4000s: %.3000s", path, why ? why : "unknown error");
        return;
    }
#define RESOLVE(ret, name, params)                                                            \
    *(void**)(&stock.name) = dlsym(handle, #name);                                            \
    if (stock.name == NULL) {                                                                 \
        snprintf(load_error, sizeof load_error, "%.4000s lacks the function %s", path, #name);     \
        dlclose(handle);                                                                      \
        return;                                                                               \
    }
    STOCK_FUNCTIONS(RESOLVE)
#undef RESOLVE
    guard_stock_exit(handle, path);
    stock_handle = handle;
    load_error[0] = '\0';
}

__attribute__((destructor)) static void unload_stock(void)
{
    if (stock_handle != NULL) {
        dlclose(stock_handle);      /* pythonfmu's own unload hook runs, as without this layer */
        stock_handle = NULL;
    }
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
    if (in == NULL) return fmi2Error;                         \
    in->requested = fmi2OK

/* -- FMI 2.0 functions ----------------------------------------------------------------------- */
EXPORT const char* fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char* fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn)
{
    if (functions == NULL) return NULL;
    if (stock_handle == NULL) {
        char text[sizeof load_error + 64];
        snprintf(text, sizeof text, "robofmu: cannot instantiate: pythonfmu's export library: %s", load_error);
        emit(functions, instanceName, fmi2Fatal, category_of_status(fmi2Fatal), text);
        return NULL;
    }
    Instance* in = calloc(1, sizeof *in);
    if (in == NULL) return NULL;
    in->outer = functions;
    in->inner = *functions;
    in->inner.logger = filter;
    in->inner.componentEnvironment = in;
    in->logging_on = loggingOn ? 1 : 0;
    in->stock = stock.fmi2Instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation,
                                      &in->inner, visible, fmi2True);
    if (in->stock == NULL) {            /* pythonfmu has logged why (fmi2Fatal: always shown) */
        free(in);
        return NULL;
    }
    return in;
}

EXPORT void fmi2FreeInstance(fmi2Component c)
{
    Instance* in = (Instance*)c;
    if (in == NULL) return;
    stock.fmi2FreeInstance(in->stock);
    free_categories(in);
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
FORWARD0(fmi2Reset)
FORWARD0(fmi2CancelStep)

#define FORWARD_VALUES(name, type)                                                            \
    EXPORT fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, type value[]) \
    {                                                                                         \
        ENTER(c);                                                                      \
        return finish(in, stock.name(in->stock, vr, nvr, value));                             \
    }
FORWARD_VALUES(fmi2GetReal, fmi2Real)
FORWARD_VALUES(fmi2GetInteger, fmi2Integer)
FORWARD_VALUES(fmi2GetBoolean, fmi2Boolean)
FORWARD_VALUES(fmi2GetString, fmi2String)
FORWARD_VALUES(fmi2SetReal, const fmi2Real)
FORWARD_VALUES(fmi2SetInteger, const fmi2Integer)
FORWARD_VALUES(fmi2SetBoolean, const fmi2Boolean)
FORWARD_VALUES(fmi2SetString, const fmi2String)

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
    return finish(in, stock.fmi2DoStep(in->stock, currentCommunicationPoint, communicationStepSize,
                                       noSetFMUStatePriorToCurrentPoint));
}

#define FORWARD_STATUS(name, type)                                                            \
    EXPORT fmi2Status name(fmi2Component c, const fmi2StatusKind s, type* value)              \
    {                                                                                         \
        ENTER(c);                                                                      \
        return finish(in, stock.name(in->stock, s, value));                                   \
    }
FORWARD_STATUS(fmi2GetStatus, fmi2Status)
FORWARD_STATUS(fmi2GetRealStatus, fmi2Real)
FORWARD_STATUS(fmi2GetIntegerStatus, fmi2Integer)
FORWARD_STATUS(fmi2GetBooleanStatus, fmi2Boolean)
FORWARD_STATUS(fmi2GetStringStatus, fmi2String)
