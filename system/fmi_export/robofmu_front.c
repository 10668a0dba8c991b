/* A front for a third-party FMI 2.0 co-simulation library that logs a debug trace as an error.

   robofmu's FMU containers carry, in binaries/linux64/, this library as <modelIdentifier>.so and
   fmu-manipulation-toolbox's container runtime, unchanged, as libcontainer-runtime.so
   (robofmu.system.container). The importer loads this one; it loads the runtime from its own
   folder and forwards every FMI function to it, changing one thing: the runtime (2.0) logs
   "Solver configure...." with status fmi2Error at every fmi2Instantiate of a successful run, a
   trace of its solver set-up (robofmu.system.container says where), so hosts that count
   logged errors report a correct run as failed. A message listed in CHATTER, logged with status
   fmi2Error, reaches the importer as what it is: an fmi2OK message with the category "logAll",
   only while debug logging is on (fmi2Instantiate's loggingOn, then fmi2SetDebugLogging).
   Every other message, status and call is the runtime's, untouched. */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2_forward.h"

#define EXPORT __attribute__((visibility("default")))
#define BEHIND_LIBRARY "libcontainer-runtime.so"

/* The runtime's error-level messages that are not errors (the text exactly). */
static const char* const CHATTER[] = {"Solver configure...."};

static struct {
#define FIELD(ret, name, params) ret (*name) params;
    FORWARDED_FUNCTIONS(FIELD)
#undef FIELD
    fmi2Status (*fmi2SetDebugLogging)(fmi2Component, fmi2Boolean, size_t, const fmi2String[]);
} behind;

static void* behind_handle = NULL;
static pthread_mutex_t load_lock = PTHREAD_MUTEX_INITIALIZER;

typedef struct {
    fmi2CallbackFunctions inner;            /* handed to the runtime: its logger is relay() */
    const fmi2CallbackFunctions* outer;     /* the importer's */
    fmi2Component component;                /* the runtime's instance */
    int logging_on;
} Front;

static int is_chatter(fmi2Status status, fmi2String message)
{
    if (status != fmi2Error || message == NULL) return 0;
    for (size_t k = 0; k < sizeof CHATTER / sizeof *CHATTER; ++k) {
        if (strcmp(message, CHATTER[k]) == 0) return 1;
    }
    return 0;
}

/* The runtime's logger: its message formatted (it passes a format and arguments), chatter
   downgraded, and passed on with every '%' doubled (the importer's logger takes a format). */
static void relay(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                  fmi2String message, ...)
{
    Front* front = (Front*)env;
    if (front == NULL || front->outer == NULL || front->outer->logger == NULL) return;
    char text[4096];
    va_list args;
    va_start(args, message);
    vsnprintf(text, sizeof text, message ? message : "", args);
    va_end(args);
    if (is_chatter(status, text)) {
        if (!front->logging_on) return;
        status = fmi2OK;
        category = "logAll";
    }
    char escaped[2 * sizeof text];
    char* q = escaped;
    for (const char* p = text; *p; ++p) {
        *q++ = *p;
        if (*p == '%') *q++ = '%';
    }
    *q = '\0';
    front->outer->logger(front->outer->componentEnvironment, name, status, category, escaped);
}

/* The runtime, from the folder of this library: 1, or 0 with the reason. */
static int load_behind(char* error, size_t size)
{
    char path[4096];
    void* handle = load_beside((const void*)&load_behind, BEHIND_LIBRARY, path, sizeof path, error, size);
    if (handle == NULL) return 0;
#define RESOLVE(ret, name, params)                                                            \
    *(void**)(&behind.name) = dlsym(handle, #name);                                           \
    if (behind.name == NULL) {                                                                \
        snprintf(error, size, "%.3000s lacks the function %s", path, #name);                  \
        dlclose(handle);                                                                      \
        return 0;                                                                             \
    }
    FORWARDED_FUNCTIONS(RESOLVE)
    RESOLVE(fmi2Status, fmi2SetDebugLogging, ())
#undef RESOLVE
    behind_handle = handle;
    return 1;
}

__attribute__((destructor)) static void unload_behind(void)
{
    if (behind_handle != NULL) dlclose(behind_handle);
    behind_handle = NULL;
}

/* The marker of this library (tests). */
EXPORT const char* robofmu_front_library(void)
{
    return "robofmu FMI 2.0 front library";
}

EXPORT const char* fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char* fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn)
{
    if (functions == NULL) return NULL;
    char error[8192];
    pthread_mutex_lock(&load_lock);
    int loaded = behind_handle != NULL || load_behind(error, sizeof error);
    pthread_mutex_unlock(&load_lock);
    Front* front = loaded ? calloc(1, sizeof *front) : NULL;
    if (front == NULL) {
        if (!loaded && functions->logger != NULL)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                              "fmi2Instantiate: cannot instantiate: %s", error);
        return NULL;
    }
    front->outer = functions;
    front->inner = *functions;
    front->inner.logger = relay;
    front->inner.componentEnvironment = front;
    front->logging_on = loggingOn ? 1 : 0;
    front->component = behind.fmi2Instantiate(instanceName, fmuType, fmuGUID, fmuResourceLocation, &front->inner,
                                              visible, loggingOn);
    if (front->component == NULL) {
        free(front);
        return NULL;
    }
    return front;
}

EXPORT void fmi2FreeInstance(fmi2Component c)
{
    Front* front = (Front*)c;
    if (front == NULL) return;
    behind.fmi2FreeInstance(front->component);
    free(front);
}

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                      const fmi2String categories[])
{
    Front* front = (Front*)c;
    if (front == NULL) return fmi2Error;
    front->logging_on = loggingOn ? 1 : 0;
    return behind.fmi2SetDebugLogging(front->component, loggingOn, nCategories, categories);
}

/* Every other function: the runtime's, with its instance. The parameter lists are spelled out
   for the arguments' names; FORWARDED_FUNCTIONS checks the set (a missing one fails to link). */
#define COMPONENT(c) (((Front*)(c))->component)
#define GUARD(c) if ((c) == NULL) return fmi2Error

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean td, fmi2Real tol, fmi2Real t0, fmi2Boolean sd, fmi2Real t1)
{ GUARD(c); return behind.fmi2SetupExperiment(COMPONENT(c), td, tol, t0, sd, t1); }
EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c) { GUARD(c); return behind.fmi2EnterInitializationMode(COMPONENT(c)); }
EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c) { GUARD(c); return behind.fmi2ExitInitializationMode(COMPONENT(c)); }
EXPORT fmi2Status fmi2Terminate(fmi2Component c) { GUARD(c); return behind.fmi2Terminate(COMPONENT(c)); }
EXPORT fmi2Status fmi2Reset(fmi2Component c) { GUARD(c); return behind.fmi2Reset(COMPONENT(c)); }
EXPORT fmi2Status fmi2CancelStep(fmi2Component c) { GUARD(c); return behind.fmi2CancelStep(COMPONENT(c)); }

#define VALUES(name, type)                                                                     \
    EXPORT fmi2Status name(fmi2Component c, const fmi2ValueReference vr[], size_t n, type value[]) \
    { GUARD(c); return behind.name(COMPONENT(c), vr, n, value); }
VALUES(fmi2GetReal, fmi2Real)
VALUES(fmi2GetInteger, fmi2Integer)
VALUES(fmi2GetBoolean, fmi2Boolean)
VALUES(fmi2GetString, fmi2String)
VALUES(fmi2SetReal, const fmi2Real)
VALUES(fmi2SetInteger, const fmi2Integer)
VALUES(fmi2SetBoolean, const fmi2Boolean)
VALUES(fmi2SetString, const fmi2String)

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate* s) { GUARD(c); return behind.fmi2GetFMUstate(COMPONENT(c), s); }
EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { GUARD(c); return behind.fmi2SetFMUstate(COMPONENT(c), s); }
EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate* s) { GUARD(c); return behind.fmi2FreeFMUstate(COMPONENT(c), s); }
EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t* n)
{ GUARD(c); return behind.fmi2SerializedFMUstateSize(COMPONENT(c), s, n); }
EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n)
{ GUARD(c); return behind.fmi2SerializeFMUstate(COMPONENT(c), s, b, n); }
EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate* s)
{ GUARD(c); return behind.fmi2DeSerializeFMUstate(COMPONENT(c), b, n, s); }
EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                               const fmi2ValueReference k[], size_t nk, const fmi2Real dk[], fmi2Real du[])
{ GUARD(c); return behind.fmi2GetDirectionalDerivative(COMPONENT(c), u, nu, k, nk, dk, du); }
EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                              const fmi2Integer order[], const fmi2Real value[])
{ GUARD(c); return behind.fmi2SetRealInputDerivatives(COMPONENT(c), vr, n, order, value); }
EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n,
                                               const fmi2Integer order[], fmi2Real value[])
{ GUARD(c); return behind.fmi2GetRealOutputDerivatives(COMPONENT(c), vr, n, order, value); }
EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean no_set_prior)
{ GUARD(c); return behind.fmi2DoStep(COMPONENT(c), t, h, no_set_prior); }

#define STATUS(name, type)                                                                     \
    EXPORT fmi2Status name(fmi2Component c, const fmi2StatusKind s, type* value)               \
    { GUARD(c); return behind.name(COMPONENT(c), s, value); }
STATUS(fmi2GetStatus, fmi2Status)
STATUS(fmi2GetRealStatus, fmi2Real)
STATUS(fmi2GetIntegerStatus, fmi2Integer)
STATUS(fmi2GetBooleanStatus, fmi2Boolean)
STATUS(fmi2GetStringStatus, fmi2String)
