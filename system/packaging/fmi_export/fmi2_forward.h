/* The FMI 2.0 co-simulation types and the functions a front library forwards to the library
   behind it: shared by robofmu_fmi2.c (in front of pythonfmu's) and robofmu_front.c (in front of
   fmu-manipulation-toolbox's container runtime). */
#ifndef ROBOFMU_FMI2_FORWARD_H
#define ROBOFMU_FMI2_FORWARD_H

#include <dlfcn.h>
#include <stddef.h>
#include <stdio.h>
#include <string.h>

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

/* -- the functions forwarded to the library behind ------------------------------------------ */
#define FORWARDED_FUNCTIONS(X) \
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


/* The library `name` from the folder of the library that holds `self` (an address inside it),
   loaded (RTLD_NOW | RTLD_LOCAL): its handle, its path in `path`; or NULL with the reason in
   `error`. Each of the front libraries then resolves FORWARDED_FUNCTIONS from it. */
static inline void* load_beside(const void* self, const char* name, char* path, size_t size, char* error,
                                size_t error_size)
{
    Dl_info info;
    if (!dladdr(self, &info) || info.dli_fname == NULL) {
        snprintf(error, error_size, "cannot find the folder of this library");
        return NULL;
    }
    const char* slash = strrchr(info.dli_fname, '/');
    size_t dir = slash ? (size_t)(slash - info.dli_fname) + 1 : 0;
    if (dir + strlen(name) + 1 > size) {
        snprintf(error, error_size, "the path of %.3000s is too long", info.dli_fname);
        return NULL;
    }
    memcpy(path, info.dli_fname, dir);
    strcpy(path + dir, name);
    void* handle = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (handle == NULL) {
        const char* why = dlerror();
        snprintf(error, error_size, "cannot load %.3000s: %.3000s", path, why ? why : "unknown error");
    }
    return handle;
}

/* In a loader that got `handle` from load_beside (its path in `path`): resolve the function
   `name` into `table`.name or, if the library lacks it, write why into `error` (of `size`
   bytes), close `handle` and return 0 from the loader. */
#define RESOLVE_BESIDE(table, name)                                                           \
    *(void**)(&(table).name) = dlsym(handle, #name);                                          \
    if ((table).name == NULL) {                                                               \
        snprintf(error, size, "%.3000s lacks the function %s", path, #name);                  \
        dlclose(handle);                                                                      \
        return 0;                                                                             \
    }

#endif
