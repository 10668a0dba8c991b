/* For tests/test_c_host.py: what a host that frees its FMUs from C++ static destructors does
   (OMSimulator's Python API and CLI). free_at_exit(terminate, free, c) registers a C exit handler
   that terminates and frees FMU instance c; in a Python process exit() runs it after the
   interpreter was finalized. It prints `late: terminate STATUS, freed`. */
#include <stdio.h>
#include <stdlib.h>

typedef int (*Terminate)(void*);
typedef void (*Free)(void*);

static Terminate terminate_fn;
static Free free_fn;
static void* component;

static void later(void)
{
    int status = terminate_fn(component);
    free_fn(component);
    printf("late: terminate %d, freed\n", status);
    fflush(stdout);
}

int free_at_exit(Terminate terminate, Free free_instance, void* c)
{
    terminate_fn = terminate;
    free_fn = free_instance;
    component = c;
    return atexit(later);
}
