/*
 * surrogate.h: evaluating a surrogate of `cosim surrogate` (src/cosim/analysis/surrogate/models.py) in C.
 *
 * The numbers come from DIR/surrogate/models.json, written into a generated C file by
 * `cosim export-surrogate` (src/cosim/export/surrogate_fmu.py). The formulas and the order of every sum are
 * those of models.py's predict(), so the FMU's outputs equal the Python predictions.
 */
#ifndef COSIM_SURROGATE_H
#define COSIM_SURROGATE_H

#include <stddef.h>

typedef enum { SURROGATE_GP = 0, SURROGATE_POLY = 1 } SurrogateKind;
typedef enum { SHAPE_MATERN32 = 0, SHAPE_MATERN52 = 1, SHAPE_RBF = 2 } KernelShape;

typedef struct {
    SurrogateKind kind;
    size_t n_params;
    const double *low, *span; /* the unit box of the training designs: z = (x - low) / span */
    double y_mean, y_scale;   /* objective = y_mean + y_scale * standardised prediction */
    /* Gaussian process: c * k(d) + noise, d = |(z - x_i) / length_scales| */
    KernelShape shape;
    double constant, noise;
    const double *length_scales;
    size_t n_train;
    const double *x_train;  /* n_train x n_params, row-major, in the unit box */
    const double *alpha;    /* n_train */
    const double *cholesky; /* n_train x n_train, row-major, lower triangular */
    /* polynomial: intercept + sum_t coefficients[t] * prod_j z_j^powers[t][j]; its std is `error` everywhere */
    size_t n_terms;
    const int *powers; /* n_terms x n_params, row-major */
    const double *coefficients;
    double intercept, error;
} Surrogate;

/* The prediction and its standard deviation at the design x (n_params values). `work` holds 2 * n_train
 * doubles (a GP's kernel vector and forward substitution; unused by a polynomial). */
void surrogate_predict(const Surrogate *s, const double *x, double *work, double *mean, double *std);

#endif
