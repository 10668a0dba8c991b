/* The master's call list: the FMI 2.0 calls of one exchange (or of one round of steps) made in
 * one call from Python instead of one ctypes call each.
 *
 * system/call_list.py compiles this file with the machine's C compiler (cached), loads it with
 * ctypes.PyDLL (the caller keeps the GIL, as for the single calls) and fills an array of
 * robofmu_call records from the same ports, buffers and function pointers the single calls use
 * (system/exchange.py). The calls are made in the array's order, exactly as the loop over the
 * single calls makes them; the first whose status is fmi2Error or worse stops the list.
 *
 * No Python here and no allocation: every pointer is to memory the master made once per run.
 * The record's layout is checked from Python at load time (robofmu_call_size, robofmu_call_offsets).
 */
#include <stddef.h>
#include <string.h>

#define EXPORT __attribute__((visibility("default")))

typedef int (*get_real_t)(void *, const unsigned int *, size_t, double *);
typedef int (*set_real_t)(void *, const unsigned int *, size_t, const double *);
typedef int (*get_boolean_t)(void *, const unsigned int *, size_t, int *);
typedef int (*set_boolean_t)(void *, const unsigned int *, size_t, const int *);
typedef int (*do_step_t)(void *, double, double, int);

enum { GET_REAL = 0, SET_REAL = 1, GET_BOOLEAN = 2, SET_BOOLEAN = 3, DO_STEP = 4 };

typedef struct {
    long kind;                      /* GET_REAL ... DO_STEP */
    void *function;                 /* the FMU's fmi2GetReal ... fmi2DoStep */
    void *component;                /* its fmi2Component */
    const unsigned int *references; /* value references, count of them */
    size_t count;
    void *values;                   /* double[count] (Real) or int[count] (Boolean) */
    const void *signals;            /* set from a gather: the signal vector (double or int), else NULL */
    const ptrdiff_t *sources;       /* ... and the indices in it, count of them */
    int *last;                      /* SET_BOOLEAN: the values last set, count of them */
    int *have_last;                 /* SET_BOOLEAN: whether last holds any yet */
    const double *time;             /* DO_STEP: the communication point */
    double step;                    /* DO_STEP: the step size */
} robofmu_call;

EXPORT size_t robofmu_call_size(void) { return sizeof(robofmu_call); }

/* The offsets of the record's fields, in the order declared, into offsets[0..11]. */
EXPORT void robofmu_call_offsets(size_t *offsets)
{
    size_t k = 0;
    offsets[k++] = offsetof(robofmu_call, kind);
    offsets[k++] = offsetof(robofmu_call, function);
    offsets[k++] = offsetof(robofmu_call, component);
    offsets[k++] = offsetof(robofmu_call, references);
    offsets[k++] = offsetof(robofmu_call, count);
    offsets[k++] = offsetof(robofmu_call, values);
    offsets[k++] = offsetof(robofmu_call, signals);
    offsets[k++] = offsetof(robofmu_call, sources);
    offsets[k++] = offsetof(robofmu_call, last);
    offsets[k++] = offsetof(robofmu_call, have_last);
    offsets[k++] = offsetof(robofmu_call, time);
    offsets[k++] = offsetof(robofmu_call, step);
}

/* Make calls[0..n-1] in order. Returns 0, or the status (> 1) of the first call that returned
 * fmi2Error or worse, its index in *failed; an unknown kind returns 4 (fmi2Fatal). */
EXPORT int robofmu_run_calls(const robofmu_call *calls, size_t n, size_t *failed)
{
    for (size_t i = 0; i < n; i++) {
        const robofmu_call *c = calls + i;
        int status;
        switch (c->kind) {
        case GET_REAL:
            status = ((get_real_t)c->function)(c->component, c->references, c->count, (double *)c->values);
            break;
        case SET_REAL:
            if (c->signals) {
                const double *from = (const double *)c->signals;
                double *to = (double *)c->values;
                for (size_t j = 0; j < c->count; j++) to[j] = from[c->sources[j]];
            }
            status = ((set_real_t)c->function)(c->component, c->references, c->count, (const double *)c->values);
            break;
        case GET_BOOLEAN:
            status = ((get_boolean_t)c->function)(c->component, c->references, c->count, (int *)c->values);
            break;
        case SET_BOOLEAN: {
            /* discrete inputs: set only when they changed since the last set that succeeded */
            const int *from = (const int *)c->signals;
            int *to = (int *)c->values;
            int same = *c->have_last;
            for (size_t j = 0; j < c->count; j++) {
                to[j] = from[c->sources[j]];
                same = same && to[j] == c->last[j];
            }
            if (same) { status = 0; break; }
            status = ((set_boolean_t)c->function)(c->component, c->references, c->count, to);
            if (status <= 1) {
                memcpy(c->last, to, c->count * sizeof(int));
                *c->have_last = 1;
            }
            break;
        }
        case DO_STEP:
            status = ((do_step_t)c->function)(c->component, *c->time, c->step, 1);
            break;
        default:
            status = 4;
        }
        if (status > 1) {
            *failed = i;
            return status;
        }
    }
    return 0;
}
