/*
 * structural: arrays sized by FMI 3.0 structural parameters, like the Reference FMU StateSpace.
 * n (UInt64, 1..8, default 3) and m (1..4, default 2) are structural parameters; they size
 *   u[n] (input), y[n] = k * u + (i + 1) * t   (i = 0 .. n-1)   and   z[n][m] = 10 i + j + t.
 * n and m can only be set in Configuration Mode (fmi3EnterConfigurationMode), as FMI 3.0 prescribes.
 */
#include <stdbool.h>
#include <stddef.h>
#include <stdint.h>

#define MAX_N 8
#define MAX_M 4

struct Model {
    double time;
    uint64_t n, m;
    double k;
    double u[MAX_N], y[MAX_N], z[MAX_N * MAX_M];
};

#include "../fmi3_runtime.c"

static void outputs(Instance *I) {
    struct Model *d = &I->m;
    for (size_t i = 0; i < d->n; i++) {
        d->y[i] = d->k * d->u[i] + (double)(i + 1) * I->time;
        for (size_t j = 0; j < d->m; j++) d->z[i * d->m + j] = 10.0 * (double)i + (double)j + I->time;
    }
}

static bool model_variable(Instance *I, fmi3ValueReference vr, Var *v) {
    struct Model *d = &I->m;
    d->time = I->time;
    if (I->state == S_STEP || I->state == S_INITIALIZATION) outputs(I);
    switch (vr) {
    case 0: *v = (Var){T_F64, &d->time, 1, K_READ_ONLY}; return true;
    case 1: *v = (Var){T_U64, &d->n, 1, K_STRUCTURAL}; return true;
    case 2: *v = (Var){T_U64, &d->m, 1, K_STRUCTURAL}; return true;
    case 3: *v = (Var){T_F64, &d->k, 1, K_PARAMETER}; return true;
    case 4: *v = (Var){T_F64, d->u, d->n, K_INPUT}; return true;
    case 5: *v = (Var){T_F64, d->y, d->n, K_READ_ONLY}; return true;
    case 6: *v = (Var){T_F64, d->z, d->n * d->m, K_READ_ONLY}; return true;
    default: return false;
    }
}

static void model_start(Instance *I) {
    struct Model *d = &I->m;
    d->n = 3;
    d->m = 2;
    d->k = 2.0;
    for (size_t i = 0; i < MAX_N; i++) d->u[i] = (double)(i + 1);
}

static fmi3Status model_exit_init(Instance *I) {
    struct Model *d = &I->m;
    if (d->n < 1 || d->n > MAX_N || d->m < 1 || d->m > MAX_M) {
        log_error(I, "n must be in 1..%d and m in 1..%d, got n=%llu m=%llu", MAX_N, MAX_M,
                  (unsigned long long)d->n, (unsigned long long)d->m);
        return fmi3Error;
    }
    outputs(I);
    return fmi3OK;
}

static fmi3Status model_step(Instance *I, double t, double h, double *stop_at) {
    (void)t; (void)h; (void)stop_at;
    return fmi3OK;
}
