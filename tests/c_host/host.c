/* A plain C FMI 2.0 co-simulation host, for tests/test_c_host.py: what fmusim, the OMSimulator
   CLI or a C++ tool do with a robofmu FMU, reduced to the calls that matter.

   usage: host FOLDER IDENTIFIER SCENARIO [STEPS [VR]]
     FOLDER      an extracted FMU (binaries/linux64/IDENTIFIER.so, resources/)
     SCENARIO    run           instantiate, initialize, STEPS steps of 1 ms (default 10), print
                               the Real of value reference VR (default 0), terminate twice,
                               free; exit 0
                 atexit-free   as run, but the instance is terminated twice and freed (twice
                               the FMI calls after it) from an atexit handler registered before
                               the library was loaded: it runs after the library's own exit
                               handler has finalized the embedded interpreter
                 no-resources  instantiate with FOLDER/resources, which the caller deleted: must
                               return NULL after logging why; exit 0 if it did
                 thread        as run, the steps made from a second thread
                 two           two instances, freed in the order they were made (first first)

   Every message the FMU logs is printed as `log STATUS CATEGORY: MESSAGE`; results as
   `value NAME = X`; the host's own verdicts as `host: ...`. Nothing else. */
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static const char* STATUS[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    (void)env;
    (void)name;
    char text[4096];
    va_list args;
    va_start(args, message);
    vsnprintf(text, sizeof text, message, args);
    va_end(args);
    printf("log %s %s: %s\n", status <= fmi2Pending ? STATUS[status] : "?", category ? category : "", text);
    fflush(stdout);
}

static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

static struct {
    fmi2InstantiateTYPE* instantiate;
    fmi2FreeInstanceTYPE* free_instance;
    fmi2SetupExperimentTYPE* setup;
    fmi2EnterInitializationModeTYPE* enter;
    fmi2ExitInitializationModeTYPE* exit_init;
    fmi2DoStepTYPE* do_step;
    fmi2GetRealTYPE* get_real;
    fmi2TerminateTYPE* terminate;
} fmi;

static fmi2Component pending_free = NULL;
static int steps = 10;
static fmi2ValueReference output = 0;

static void* find(void* library, const char* name)
{
    void* f = dlsym(library, name);
    if (f == NULL) {
        printf("host: %s is missing: %s\n", name, dlerror());
        exit(3);
    }
    return f;
}

static fmi2Component instantiate(const char* name, const char* resources)
{
    char uri[8192];
    snprintf(uri, sizeof uri, "file://%s", resources);
    return fmi.instantiate(name, fmi2CoSimulation, "", uri, &callbacks, fmi2False, fmi2False);
}

static int initialize(fmi2Component c)
{
    return fmi.setup(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) == fmi2OK && fmi.enter(c) == fmi2OK
        && fmi.exit_init(c) == fmi2OK;
}

static void* stepping(void* c)
{
    for (int k = 0; k < steps; ++k) {
        fmi2Status s = fmi.do_step((fmi2Component)c, k * 1e-3, 1e-3, fmi2True);
        if (s != fmi2OK) {
            printf("host: fmi2DoStep %d returned %s\n", k, STATUS[s]);
            return (void*)1;
        }
    }
    return NULL;
}

static void report(fmi2Component c)
{
    fmi2Real value = 0.0;
    fmi2Status s = fmi.get_real(c, &output, 1, &value);
    printf("value vr%u = %.17g (%s)\n", output, value, STATUS[s]);
}

static void free_at_exit(void)
{
    if (pending_free == NULL) return;
    fmi2Status first = fmi.terminate(pending_free);
    fmi2Status second = fmi.terminate(pending_free);
    fmi2ValueReference vr = 0;
    fmi2Real value = 0.0;
    fmi2Status get = fmi.get_real(pending_free, &vr, 1, &value);
    fmi2Status step = fmi.do_step(pending_free, 0.0, 1e-3, fmi2True);
    fmi.free_instance(pending_free);
    printf("host: after exit: terminate %s, terminate %s, get %s, step %s, freed\n", STATUS[first],
           STATUS[second], STATUS[get], STATUS[step]);
    fflush(stdout);
}

int main(int argc, char** argv)
{
    if (argc < 4) {
        printf("usage: host FOLDER IDENTIFIER run|atexit-free|no-resources|thread|two [STEPS]\n");
        return 2;
    }
    const char* folder = argv[1];
    const char* identifier = argv[2];
    const char* scenario = argv[3];
    if (argc > 4) steps = atoi(argv[4]);
    if (argc > 5) output = (fmi2ValueReference)strtoul(argv[5], NULL, 10);
    if (strcmp(scenario, "atexit-free") == 0) atexit(free_at_exit);   /* before the library loads */

    char path[8192];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", folder, identifier);
    void* library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (library == NULL) {
        printf("host: cannot load %s: %s\n", path, dlerror());
        return 3;
    }
    *(void**)&fmi.instantiate = find(library, "fmi2Instantiate");
    *(void**)&fmi.free_instance = find(library, "fmi2FreeInstance");
    *(void**)&fmi.setup = find(library, "fmi2SetupExperiment");
    *(void**)&fmi.enter = find(library, "fmi2EnterInitializationMode");
    *(void**)&fmi.exit_init = find(library, "fmi2ExitInitializationMode");
    *(void**)&fmi.do_step = find(library, "fmi2DoStep");
    *(void**)&fmi.get_real = find(library, "fmi2GetReal");
    *(void**)&fmi.terminate = find(library, "fmi2Terminate");

    char resources[8192];
    snprintf(resources, sizeof resources, "%s/resources", folder);
    if (strcmp(scenario, "no-resources") == 0) {
        fmi2Component c = instantiate("block", resources);
        printf("host: fmi2Instantiate returned %s\n", c == NULL ? "NULL" : "an instance");
        return c == NULL ? 0 : 1;
    }
    fmi2Component c = instantiate("block", resources);
    if (c == NULL) {
        printf("host: fmi2Instantiate returned NULL\n");
        return 1;
    }
    fmi2Component other = NULL;
    if (strcmp(scenario, "two") == 0) {
        other = instantiate("other", resources);
        if (other == NULL || !initialize(other)) {
            printf("host: the second instance failed\n");
            return 1;
        }
    }
    if (!initialize(c)) {
        printf("host: initialization failed\n");
        return 1;
    }
    void* failed = NULL;
    if (strcmp(scenario, "thread") == 0) {
        pthread_t thread;
        if (pthread_create(&thread, NULL, stepping, c) != 0 || pthread_join(thread, &failed) != 0) {
            printf("host: no thread\n");
            return 1;
        }
    } else {
        failed = stepping(c);
    }
    if (failed != NULL) return 1;
    report(c);
    if (strcmp(scenario, "atexit-free") == 0) {
        pending_free = c;
        printf("host: exiting with the instance alive\n");
        fflush(stdout);
        return 0;
    }
    fmi2Status first = fmi.terminate(c);
    fmi2Status second = fmi.terminate(c);
    printf("host: terminate %s, terminate %s\n", STATUS[first], STATUS[second]);
    fmi.free_instance(c);
    if (other != NULL) {
        stepping(other);
        report(other);
        fmi.terminate(other);
        fmi.free_instance(other);
    }
    printf("host: done\n");
    return 0;
}
