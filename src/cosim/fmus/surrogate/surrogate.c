/* surrogate.c: see surrogate.h. No global state: many instances may share the constant model numbers. */
#include <math.h>

#include "surrogate.h"

static double kernel_shape(double distance, KernelShape shape) {
    double s;
    switch (shape) {
    case SHAPE_MATERN32:
        s = sqrt(3.0) * distance;
        return (1.0 + s) * exp(-s);
    case SHAPE_MATERN52:
        s = sqrt(5.0) * distance;
        return (1.0 + s + s * s / 3.0) * exp(-s);
    default:
        return exp(-0.5 * distance * distance);
    }
}

static void gp_predict(const Surrogate *s, const double *z, double *work, double *mean, double *var) {
    const size_t n = s->n_train, d = s->n_params;
    double *k = work, *v = work + n;
    double m = 0.0, squares = 0.0;
    size_t i, j;
    for (i = 0; i < n; i++) {
        double squared = 0.0;
        for (j = 0; j < d; j++) {
            double step = (z[j] - s->x_train[i * d + j]) / s->length_scales[j];
            squared = squared + step * step;
        }
        k[i] = s->constant * kernel_shape(sqrt(squared), s->shape);
    }
    for (i = 0; i < n; i++) m = m + k[i] * s->alpha[i];
    for (i = 0; i < n; i++) { /* v = L^-1 k */
        double r = k[i];
        for (j = 0; j < i; j++) r -= s->cholesky[i * n + j] * v[j];
        v[i] = r / s->cholesky[i * n + i];
    }
    for (i = 0; i < n; i++) squares = squares + v[i] * v[i];
    *mean = m;
    *var = s->constant + s->noise - squares;
}

static double poly_predict(const Surrogate *s, const double *z) {
    const size_t d = s->n_params;
    double m = s->intercept;
    size_t t, j;
    int p;
    for (t = 0; t < s->n_terms; t++) {
        double term = 1.0;
        for (j = 0; j < d; j++)
            for (p = 0; p < s->powers[t * d + j]; p++) term *= z[j];
        m = m + term * s->coefficients[t];
    }
    return m;
}

void surrogate_predict(const Surrogate *s, const double *x, double *work, double *mean, double *std) {
    double z[64]; /* the export refuses more parameters */
    double m, var;
    size_t j;
    for (j = 0; j < s->n_params && j < 64; j++) z[j] = (x[j] - s->low[j]) / s->span[j];
    if (s->kind == SURROGATE_GP) {
        gp_predict(s, z, work, &m, &var);
        *std = sqrt(var > 0.0 ? var : 0.0) * s->y_scale;
    } else {
        m = poly_predict(s, z);
        *std = s->error * s->y_scale;
    }
    *mean = m * s->y_scale + s->y_mean;
}
