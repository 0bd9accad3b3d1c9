/* The floor for benchmarks/master_overhead.py: two coupled linear_ode FMI 2.0 co-simulation instances stepped
 * by a hand-written C loop (per step: getReal y of both, setReal u of both, doStep both), no master at all.
 * Usage: c_harness <unzipped FMU folder> <library path> <guid> <steps> <h>; prints the loop's seconds. */
#define _POSIX_C_SOURCE 200809L
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

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
typedef int (*get_real_t)(void *, const unsigned *, size_t, double *);
typedef int (*set_real_t)(void *, const unsigned *, size_t, const double *);
typedef int (*do_step_t)(void *, double, double, int);

int main(int argc, char **argv) {
    if (argc != 8) { fprintf(stderr, "usage: %s resources_uri library guid steps h vr_y vr_u\n", argv[0]); return 2; }
    void *lib = dlopen(argv[2], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "%s\n", dlerror()); return 1; }
    instantiate_t inst = (instantiate_t)dlsym(lib, "fmi2Instantiate");
    setup_t setup = (setup_t)dlsym(lib, "fmi2SetupExperiment");
    mode_t_ enter = (mode_t_)dlsym(lib, "fmi2EnterInitializationMode");
    mode_t_ leave = (mode_t_)dlsym(lib, "fmi2ExitInitializationMode");
    get_real_t get = (get_real_t)dlsym(lib, "fmi2GetReal");
    set_real_t set = (set_real_t)dlsym(lib, "fmi2SetReal");
    do_step_t step = (do_step_t)dlsym(lib, "fmi2DoStep");
    long steps = atol(argv[4]);
    double h = atof(argv[5]);
    unsigned y = (unsigned)atol(argv[6]), u = (unsigned)atol(argv[7]);
    Callbacks cb = {quiet, calloc, free, NULL, NULL};
    void *a = inst("one", 1, argv[3], argv[1], &cb, 0, 0), *b = inst("two", 1, argv[3], argv[1], &cb, 0, 0);
    if (!a || !b) { fprintf(stderr, "fmi2Instantiate failed\n"); return 1; }
    void *c[2] = {a, b};
    for (int i = 0; i < 2; i++) {
        if (setup(c[i], 0, 0.0, 0, 0, 0.0) > 1 || enter(c[i]) > 1 || leave(c[i]) > 1) return 1;
    }
    struct timespec t0, t1;
    double ya, yb;
    int status = 0;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    for (long k = 0; k < steps; k++) {
        double t = (double)k * h;
        status |= get(a, &y, 1, &ya);
        status |= get(b, &y, 1, &yb);
        status |= set(a, &u, 1, &yb);
        status |= set(b, &u, 1, &ya);
        status |= step(a, t, h, 1);
        status |= step(b, t, h, 1);
    }
    clock_gettime(CLOCK_MONOTONIC, &t1);
    if (status > 1) { fprintf(stderr, "an FMI call failed\n"); return 1; }
    printf("%.9f %.17g\n", (double)(t1.tv_sec - t0.tv_sec) + 1e-9 * (double)(t1.tv_nsec - t0.tv_nsec), ya);
    return 0;
}
