/* The native kernel (src/cosim/master/native/kernel.c, included here as it is) driving the same two coupled
 * linear_ode FMI 2.0 instances as benchmarks/c_harness.c, with the tables NativeFixedStep builds for the ring
 * (two transfers one.y -> two.u and two.y -> one.u, the objective's column one.y probed every step), without
 * Python: so that callgrind counts the kernel's loop and nothing else (benchmarks/native_instructions.py).
 * Usage: kernel_harness <resources uri> <library> <guid> <steps> <h> <vr y> <vr u> <gauss-seidel|jacobi> */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <stdio.h>
#include <string.h>

#include "../src/cosim/master/native/kernel.c"

typedef void (*logger_t)(void *, const char *, int, const char *, const char *, ...);
typedef struct {
    logger_t logger;
    void *(*allocate)(size_t, size_t);
    void (*free_memory)(void *);
    void *step_finished;
    void *environment;
} Callbacks;

static void quiet(void *env, const char *name, int status, const char *category, const char *message, ...) {
    (void)env; (void)name; (void)status; (void)category; (void)message;
}

typedef void *(*instantiate_t)(const char *, int, const char *, const char *, const Callbacks *, int, int);
typedef int (*setup_t)(void *, int, double, double, int, double);
typedef int (*mode_t_)(void *);

int main(int argc, char **argv) {
    if (argc != 9) { fprintf(stderr, "usage: %s resources_uri library guid steps h vr_y vr_u algorithm\n", argv[0]); return 2; }
    void *lib = dlopen(argv[2], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "%s\n", dlerror()); return 1; }
    instantiate_t inst = (instantiate_t)dlsym(lib, "fmi2Instantiate");
    setup_t setup = (setup_t)dlsym(lib, "fmi2SetupExperiment");
    mode_t_ enter = (mode_t_)dlsym(lib, "fmi2EnterInitializationMode");
    mode_t_ leave = (mode_t_)dlsym(lib, "fmi2ExitInitializationMode");
    long steps = atol(argv[4]);
    double h = atof(argv[5]);
    unsigned y = (unsigned)atol(argv[6]), u = (unsigned)atol(argv[7]);
    int jacobi = strcmp(argv[8], "jacobi") == 0;
    Callbacks cb = {quiet, calloc, free, NULL, NULL};
    KUnit units[2];
    memset(units, 0, sizeof units);
    const char *names[2] = {"one", "two"};
    for (int i = 0; i < 2; i++) {
        void *c = inst(names[i], 1, argv[3], argv[1], &cb, 0, 0);
        if (!c || setup(c, 0, 0.0, 0, 0, 0.0) > 1 || enter(c) > 1 || leave(c) > 1) return 1;
        units[i].version = 2;
        units[i].component = c;
        units[i].do_step = dlsym(lib, "fmi2DoStep");
        units[i].get[0] = dlsym(lib, "fmi2GetReal");
        units[i].set[0] = dlsym(lib, "fmi2SetReal");
    }
    /* as NativeFixedStep.bind lays the ring out: Gauss-Seidel plans each unit's incoming transfer before it */
    KTransfer transfers[2] = {
        {{1, T_REAL, 1, &y, 1, 1, NULL, 0}, {0, T_REAL, 1, &u, 1, 1, NULL, 0}, 0, NULL, NULL},  /* two.y -> one.u */
        {{0, T_REAL, 1, &y, 1, 1, NULL, 0}, {1, T_REAL, 1, &u, 1, 1, NULL, 0}, 0, NULL, NULL},  /* one.y -> two.u */
    };
    int plan_start[3] = {0, 1, 2}, plan[2] = {0, 1}, column = 0;
    KProbe probe = {{0, T_REAL, 1, &y, 1, 1, NULL, 0}, &column};
    Kernel k = {2, units, jacobi, 2, transfers, plan_start, plan, 1, &probe, 1, -1, 0.0, (double)steps * h, h, steps};
    double *rows = malloc(sizeof(double) * (size_t)(steps + 1)), *times = malloc(sizeof(double) * (size_t)(steps + 1));
    long done;
    double t_end;
    KFail fail;
    int outcome = cosim_kernel_run(&k, 0.0, (double)steps * h, steps, rows, times, &done, &t_end, &fail);
    if (outcome != RUN_DONE || done != steps) { fprintf(stderr, "the kernel stopped: %d after %ld steps\n", outcome, done); return 1; }
    printf("%.17g\n", rows[steps]);
    return 0;
}
