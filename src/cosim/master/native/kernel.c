/* cosim's native stepping kernel: the fixed-step communication loop of a system of FMI 2.0 / 3.0
 * co-simulation FMUs, in C.  Python (cosim/master/native/algorithm.py) hands it the FMI functions already
 * resolved from each FMU's library, the instance handles FMPy made, the transfer table and the probe table;
 * it runs up to max_steps communication steps and records the probed columns into a preallocated array.
 *
 * Besides FMUs it plays players' tables (KUnit.version 0, as units/player.py does) and holds the values of system
 * connectors (version 1), and carries FMI 3.0 arrays (a call of many values, elements picked by position).
 * Every value is computed as the Python master computes it, so both give the same bits: the grid time
 * t_k = start + k * step (k from the nearest whole step, half to even as Python's round), conversions
 * factor * x + offset as two roundings (compiled with -ffp-contract=off: no fused multiply-add), Integer and
 * Boolean values read into a double as Python's float() of them.
 */
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <stdbool.h>

enum { T_REAL = 0, T_INT = 1, T_BOOL = 2 };
enum { CALL_DOSTEP = 0, CALL_GET = 1, CALL_SET = 2 };
enum { RUN_DONE = 0, RUN_STOPPED = 1, RUN_FAILED = 2, RUN_ENDED = 3 };

typedef int (*fmi2_do_step_t)(void *, double, double, int);
typedef int (*fmi2_get_real_t)(void *, const unsigned *, size_t, double *);
typedef int (*fmi2_get_int_t)(void *, const unsigned *, size_t, int *);
typedef int (*fmi3_do_step_t)(void *, double, double, bool, bool *, bool *, bool *, double *);
typedef int (*fmi3_get_real_t)(void *, const unsigned *, size_t, double *, size_t);
typedef int (*fmi3_get_int_t)(void *, const unsigned *, size_t, int32_t *, size_t);
typedef int (*fmi3_get_bool_t)(void *, const unsigned *, size_t, bool *, size_t);

typedef struct {
    int version;            /* 2 or 3: an FMI co-simulation instance; 0: a table player; 1: a store (connectors) */
    void *component;        /* fmi2Component / fmi3Instance */
    void *do_step;
    void *get[3];           /* by type: Real/Float64, Integer/Int32, Boolean */
    void *set[3];
    bool *event, *terminate, *early;  /* FMI 3.0 doStep's out-arguments (the unit's own) */
    double *last_time;
    /* a player (units/player.py): the table's n_samples times and rows of n_columns values, the columns that are
     * held (Integer, Boolean), how it interpolates; current: its values at its time (a store: the held values) */
    int n_samples, n_columns, mode;
    const double *times, *values;
    const unsigned char *discrete;
    double *current;
    double *time;
} KUnit;

enum { MODE_LINEAR = 0, MODE_HOLD = 1, MODE_NEAREST = 2 };

typedef struct {            /* elements of one type in one unit: one get/set call */
    int unit, type, n;      /* n: the elements the port carries */
    const unsigned *vrs;    /* the call's value references (a player's/store's: the slots in current) */
    int n_vrs, n_values;    /* the call's nValueReferences and nValues (an FMI 3.0 array has many values) */
    const int *pos;         /* NULL: element j is value j; else value pos[j] of the call */
    int partial;            /* setting it sets only some values of an array: they are read first */
} KPort;
typedef struct {
    KPort source, target;
    int convert;            /* 1: target = factor[i] * source[i] + offset[i] (Real only) */
    const double *factor, *offset;
} KTransfer;

typedef struct {
    KPort port;
    const int *columns;     /* where each value goes in a row */
} KProbe;

typedef struct {
    int n_units; const KUnit *units;
    int jacobi;                             /* 0: Gauss-Seidel, 1: Jacobi (transfers after all steps) */
    int n_transfers; const KTransfer *transfers;
    const int *plan_start;                  /* Gauss-Seidel: transfers of units[i] are plan[plan_start[i]..plan_start[i+1]) */
    const int *plan;
    int n_probes; const KProbe *probes;
    int n_columns;
    int stop_column;                        /* -1: none; else stop once that column is non-zero */
    double start, stop, step; long grid_steps;
} Kernel;

typedef struct {
    int unit, call, type, status;
    double t, h;
} KFail;

typedef union { double *d; int *i; } Buf;

/* The call's raw values (n_values of them) of port p into rd (Real) or ri (Integer, Boolean as 0/1). */
static int get_raw(const KUnit *u, const KPort *p, double *rd, int *ri, bool *rb) {
    int status;
    if (u->version < 2) {   /* a player's or a store's values: Integer as Python's round(), Boolean as bool() */
        for (int j = 0; j < p->n_values; j++) {
            double v = u->current[p->vrs[j]];
            if (p->type == T_REAL) rd[j] = v;
            else ri[j] = p->type == T_INT ? (int)nearbyint(v) : v != 0.0;
        }
        return 0;
    }
    size_t nv = (size_t)p->n_vrs, nval = (size_t)p->n_values;
    if (u->version == 2) {
        if (p->type == T_REAL) return ((fmi2_get_real_t)u->get[0])(u->component, p->vrs, nv, rd);
        status = ((fmi2_get_int_t)u->get[p->type])(u->component, p->vrs, nv, ri);
        if (p->type == T_BOOL) for (size_t j = 0; j < nv; j++) ri[j] = ri[j] != 0;  /* Python's bool() of it */
        return status;
    }
    if (p->type == T_REAL) return ((fmi3_get_real_t)u->get[0])(u->component, p->vrs, nv, rd, nval);
    if (p->type == T_INT) return ((fmi3_get_int_t)u->get[1])(u->component, p->vrs, nv, (int32_t *)ri, nval);
    status = ((fmi3_get_bool_t)u->get[2])(u->component, p->vrs, nv, rb, nval);
    for (size_t j = 0; j < nval; j++) ri[j] = rb[j] ? 1 : 0;
    return status;
}

static int set_raw(const KUnit *u, const KPort *p, const double *rd, const int *ri, bool *rb) {
    size_t nv = (size_t)p->n_vrs, nval = (size_t)p->n_values;
    if (u->version < 2) {
        for (int j = 0; j < p->n_values; j++) u->current[p->vrs[j]] = p->type == T_REAL ? rd[j] : (double)ri[j];
        return 0;
    }
    if (u->version == 2) {
        if (p->type == T_REAL) return ((int (*)(void *, const unsigned *, size_t, const double *))u->set[0])(u->component, p->vrs, nv, rd);
        return ((int (*)(void *, const unsigned *, size_t, const int *))u->set[p->type])(u->component, p->vrs, nv, ri);
    }
    if (p->type == T_REAL)
        return ((int (*)(void *, const unsigned *, size_t, const double *, size_t))u->set[0])(u->component, p->vrs, nv, rd, nval);
    if (p->type == T_INT)
        return ((int (*)(void *, const unsigned *, size_t, const int32_t *, size_t))u->set[1])(u->component, p->vrs, nv, (const int32_t *)ri, nval);
    for (size_t j = 0; j < nval; j++) rb[j] = ri[j] != 0;
    return ((int (*)(void *, const unsigned *, size_t, const bool *, size_t))u->set[2])(u->component, p->vrs, nv, rb, nval);
}

typedef struct { double *d; int *i; bool *b; } Raw;  /* room for the largest call's values */

/* The port's elements into out_d (Real) or out_i (Integer, Boolean). */
static int get_values(const KUnit *u, const KPort *p, double *out_d, int *out_i, const Raw *raw) {
    if (p->pos == NULL) return get_raw(u, p, out_d, out_i, raw->b);
    int status = get_raw(u, p, raw->d, raw->i, raw->b);
    for (int j = 0; j < p->n; j++) {
        if (p->type == T_REAL) out_d[j] = raw->d[p->pos[j]];
        else out_i[j] = raw->i[p->pos[j]];
    }
    return status;
}

/* Sets the port's elements from d (Real) or i; *got: a status of the read before a partial set (> 1: it
 * failed, nothing was set). */
static int set_values(const KUnit *u, const KPort *p, const double *d, const int *i, const Raw *raw, int *got) {
    *got = 0;
    if (p->pos == NULL) return set_raw(u, p, d, i, raw->b);
    if (p->partial) {
        *got = get_raw(u, p, raw->d, raw->i, raw->b);
        if (*got > 1) return 0;
    }
    for (int j = 0; j < p->n; j++) {
        if (p->type == T_REAL) raw->d[p->pos[j]] = d[j];
        else raw->i[p->pos[j]] = i[j];
    }
    return set_raw(u, p, raw->d, raw->i, raw->b);
}

/* A player's values at time t, as PlayerUnit._at computes them (searchsorted 'right': after an event). */
static void play(const KUnit *u, double t) {
    const double *times = u->times, *v = u->values;
    int n = u->n_samples, m = u->n_columns;
    if (n == 1 || t <= times[0]) { memcpy(u->current, v, sizeof(double) * (size_t)m); return; }
    if (t >= times[n - 1]) { memcpy(u->current, v + (size_t)(n - 1) * (size_t)m, sizeof(double) * (size_t)m); return; }
    int lo = 0, hi = n;     /* the first sample after t */
    while (lo < hi) { int mid = lo + (hi - lo) / 2; if (times[mid] <= t) lo = mid + 1; else hi = mid; }
    int i = lo - 1;
    const double *a = v + (size_t)i * (size_t)m, *b = a + m;
    if (u->mode == MODE_HOLD) { memcpy(u->current, a, sizeof(double) * (size_t)m); return; }
    double t0 = times[i], t1 = times[i + 1];
    if (u->mode == MODE_NEAREST) {
        const double *near = t - t0 <= t1 - t ? a : b;
        for (int j = 0; j < m; j++) u->current[j] = u->discrete[j] ? a[j] : near[j];
        return;
    }
    double w = (t - t0) / (t1 - t0);
    for (int j = 0; j < m; j++) {
        double x = (1.0 - w) * a[j], y = w * b[j];
        u->current[j] = u->discrete[j] ? a[j] : x + y;
    }
}

static int do_step(const KUnit *u, double t, double h) {
    if (u->version == 2) return ((fmi2_do_step_t)u->do_step)(u->component, t, h, 1);
    if (u->version == 3)
        return ((fmi3_do_step_t)u->do_step)(u->component, t, h, true, u->event, u->terminate, u->early, u->last_time);
    if (u->version == 0) { *u->time = t + h; play(u, t + h); }
    return 0;
}

#define FAIL(U, CALL, TYPE, STATUS) do { fail->unit = (U); fail->call = (CALL); fail->type = (TYPE); \
    fail->status = (STATUS); result = RUN_FAILED; goto done; } while (0)

/* Read transfer k's source into its buffers (doubles for Real, ints otherwise); returns the status. */
static int read_transfer(const Kernel *k, const KTransfer *tr, double *d, int *i, const Raw *raw) {
    const KPort *s = &tr->source;
    int status = get_values(&k->units[s->unit], s, d, i, raw);
    if (status <= 1 && tr->convert)
        for (int j = 0; j < s->n; j++) { double x = d[j] * tr->factor[j]; d[j] = x + tr->offset[j]; }
    return status;
}

/* The most elements one port needs in a buffer: its own, and the whole array a partial port reads (n_values,
 * which may exceed n when n itself is above the running maximum). */
static int max_port(int n, const KPort *p) {
    int m = p->n > n ? p->n : n;
    return p->n_values > m ? p->n_values : m;
}

/* Runs from t0 up to max_steps steps while t < t_end.  rows (max_steps + 1 rows of n_columns) gets the probe
 * at t0 and after each step (NULL: nothing recorded, no stop_when).  Returns RUN_*; *steps_out the steps
 * completed, *t_out the time reached (for RUN_FAILED / RUN_ENDED: the start of the failing step, whose
 * length is fail->h). */
int cosim_kernel_run(const Kernel *k, double t0, double t_end, long max_steps, double *rows, double *times,
                     long *steps_out, double *t_out, KFail *fail) {
    int max_n = 1;
    for (int j = 0; j < k->n_transfers; j++) max_n = max_port(max_port(max_n, &k->transfers[j].source), &k->transfers[j].target);
    for (int j = 0; j < k->n_probes; j++) max_n = max_port(max_n, &k->probes[j].port);
    size_t slots = (size_t)max_n * (size_t)(k->n_transfers + 1);
    double *dbuf = malloc(sizeof(double) * (slots + (size_t)max_n));
    int *ibuf = malloc(sizeof(int) * (slots + (size_t)max_n));
    bool *bbuf = malloc(sizeof(bool) * (size_t)max_n);
    int result = RUN_DONE, got;
    long steps = 0;
    double t = t0, h = 0.0;
    fail->unit = -1;
    if (dbuf == NULL || ibuf == NULL || bbuf == NULL) { result = -1; goto done; }
    Raw raw = { dbuf + slots, ibuf + slots, bbuf };                   /* one call's values */
    double *pd = dbuf + (size_t)max_n * (size_t)k->n_transfers;     /* the probe's slot */
    int *pi = ibuf + (size_t)max_n * (size_t)k->n_transfers;

#define PROBE(ROW) do { double *row_ = (ROW); \
        for (int p = 0; p < k->n_probes; p++) { const KProbe *pr = &k->probes[p]; \
            int st = get_values(&k->units[pr->port.unit], &pr->port, pd, pi, &raw); \
            if (st > 1) FAIL(pr->port.unit, CALL_GET, pr->port.type, st); \
            for (int j = 0; j < pr->port.n; j++) \
                row_[pr->columns[j]] = pr->port.type == T_REAL ? pd[j] : (double)pi[j]; \
        } } while (0)
#define WRITE(TR, D, I) do { const KTransfer *w_ = (TR); \
        int st_ = set_values(&k->units[w_->target.unit], &w_->target, (D), (I), &raw, &got); \
        if (got > 1) FAIL(w_->target.unit, CALL_GET, w_->target.type, got); \
        if (st_ > 1) FAIL(w_->target.unit, CALL_SET, w_->target.type, st_); } while (0)
#define STEP(U) do { const KUnit *un_ = &k->units[U]; int st_ = do_step(un_, t, h); \
        if (st_ > 1) FAIL((U), CALL_DOSTEP, 0, st_); \
        if (un_->version == 3 && (*un_->terminate || *un_->early)) { fail->unit = (U); result = RUN_ENDED; goto done; } \
        } while (0)

    if (rows != NULL) { times[0] = t0; PROBE(rows); }
    while (t < t_end && steps < max_steps) {
        long kk = (long)nearbyint((t - k->start) / k->step) + 1;
        double t_next = kk >= k->grid_steps ? k->stop : k->start + (double)kk * k->step;
        h = t_next - t;
        if (!k->jacobi) {
            for (int u = 0; u < k->n_units; u++) {
                for (int q = k->plan_start[u]; q < k->plan_start[u + 1]; q++) {
                    const KTransfer *tr = &k->transfers[k->plan[q]];
                    int st = read_transfer(k, tr, dbuf, ibuf, &raw);
                    if (st > 1) FAIL(tr->source.unit, CALL_GET, tr->source.type, st);
                    WRITE(tr, dbuf, ibuf);
                }
                STEP(u);
            }
        } else {
            for (int u = 0; u < k->n_units; u++) STEP(u);
            for (int q = 0; q < k->n_transfers; q++) {  /* every read before any write */
                const KTransfer *tr = &k->transfers[q];
                int st = read_transfer(k, tr, dbuf + (size_t)q * max_n, ibuf + (size_t)q * max_n, &raw);
                if (st > 1) FAIL(tr->source.unit, CALL_GET, tr->source.type, st);
            }
            for (int q = 0; q < k->n_transfers; q++)
                WRITE(&k->transfers[q], dbuf + (size_t)q * max_n, ibuf + (size_t)q * max_n);
        }
        t = t_next;
        steps++;
        if (rows != NULL) {
            double *row = rows + (size_t)steps * (size_t)k->n_columns;
            times[steps] = t;
            PROBE(row);
            if (k->stop_column >= 0 && row[k->stop_column] != 0.0) { result = RUN_STOPPED; goto done; }
        }
    }
done:
    fail->t = t;
    fail->h = h;
    *steps_out = steps;
    *t_out = t;
    free(dbuf); free(ibuf); free(bbuf);
    return result;
}
#undef PROBE
#undef WRITE
#undef STEP

/* ---------------------------------------------------------------------------------------------------------
 * The objective reducers (cosim.master.observers.REDUCERS) over recorded rows, numpy's arithmetic mirrored so
 * that the results are the Python reducers' bit for bit: np.trapezoid's terms (d * (y1 + y0)) / 2.0; a sum over
 * axis 0 that is numpy's pairwise summation when the reduced array has one column and a plain running sum
 * (from 0.0) when it has more (numpy then adds row after row); np.minimum/np.maximum's NaN propagation and, on
 * a tie, the second operand; np.argmax/np.argmin's first index (a NaN counts as the extreme).
 */
enum { R_FINAL, R_INITIAL, R_MIN, R_MAX, R_MEAN, R_INTEGRAL, R_INTEGRAL_ABS, R_RMS, R_TIME_OF_MAX, R_TIME_OF_MIN };

/* numpy's pairwise_sum for float64 (numpy/_core/src/umath/loops_utils.h.src), unrolled by 8 below 128 values */
static double pairwise_sum(const double *a, long n) {
    if (n < 8) {
        double res = 0.;
        for (long i = 0; i < n; i++) res += a[i];
        return res;
    }
    if (n <= 128) {
        double r[8];
        long i;
        for (int j = 0; j < 8; j++) r[j] = a[j];
        for (i = 8; i < n - (n % 8); i += 8)
            for (int j = 0; j < 8; j++) r[j] += a[i + j];
        double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
        for (; i < n; i++) res += a[i];
        return res;
    }
    long n2 = n / 2;
    n2 -= n2 % 8;
    return pairwise_sum(a, n2) + pairwise_sum(a + n2, n - n2);
}

#define X(I, J) rows[(size_t)(I) * (size_t)stride + (size_t)cols[J]]

static double integrand(int reduction, double x) {
    return reduction == R_INTEGRAL_ABS ? fabs(x) : reduction == R_RMS ? x * x : x;
}

/* np.trapezoid(y, t, axis=0) of y = x, |x| or x*x per column; scratch holds n doubles */
static void integrals(int reduction, const double *t, const double *rows, long n, int stride, int m,
                      const int *cols, double *out, double *scratch) {
    for (int j = 0; j < m; j++) out[j] = 0.0;
    if (n <= 1) return;
    if (m == 1) {
        for (long i = 0; i + 1 < n; i++) {
            double d = t[i + 1] - t[i];
            scratch[i] = (d * (integrand(reduction, X(i + 1, 0)) + integrand(reduction, X(i, 0)))) / 2.0;
        }
        out[0] = 0.0 + pairwise_sum(scratch, n - 1);
        return;
    }
    for (long i = 0; i + 1 < n; i++) {
        double d = t[i + 1] - t[i];
        for (int j = 0; j < m; j++)
            out[j] += (d * (integrand(reduction, X(i + 1, j)) + integrand(reduction, X(i, j)))) / 2.0;
    }
}

/* Reduce columns cols[0..m) of rows (n rows of stride doubles, times t) by `reduction` into out[0..m), as
 * REDUCERS[name](t, x) does for x = those columns; scratch holds n doubles.  Returns 0, or -1 for an unknown
 * reduction. */
int cosim_reduce(int reduction, const double *t, const double *rows, long n, int stride, int m, const int *cols,
                 double *out, double *scratch) {
    double duration = t[n - 1] - t[0];
    switch (reduction) {
    case R_FINAL: case R_INITIAL:
        for (int j = 0; j < m; j++) out[j] = X(reduction == R_FINAL ? n - 1 : 0, j);
        return 0;
    case R_MIN: case R_MAX:
        for (int j = 0; j < m; j++) {
            double a = X(0, j);
            for (long i = 1; i < n; i++) {
                double b = X(i, j);
                a = (isnan(a) || (reduction == R_MIN ? a < b : a > b)) ? a : b;
            }
            out[j] = a;
        }
        return 0;
    case R_TIME_OF_MAX: case R_TIME_OF_MIN:
        for (int j = 0; j < m; j++) {
            double best = X(0, j);
            long at = 0;
            for (long i = 1; i < n && !isnan(best); i++) {
                double b = X(i, j);
                if (reduction == R_TIME_OF_MAX ? !(b <= best) : !(b >= best)) { best = b; at = i; }
            }
            out[j] = t[at];
        }
        return 0;
    case R_INTEGRAL: case R_INTEGRAL_ABS:
        integrals(reduction, t, rows, n, stride, m, cols, out, scratch);
        return 0;
    case R_MEAN: case R_RMS:
        if (!(duration > 0)) {
            for (int j = 0; j < m; j++) out[j] = reduction == R_MEAN ? X(n - 1, j) : fabs(X(n - 1, j));
            return 0;
        }
        integrals(reduction, t, rows, n, stride, m, cols, out, scratch);
        for (int j = 0; j < m; j++) out[j] = reduction == R_MEAN ? out[j] / duration : sqrt(out[j] / duration);
        return 0;
    }
    return -1;
}
#undef X

/* cosim_reduce for each of codes[0..k): out is k rows of m values.  Returns 0, or -1 for an unknown code. */
int cosim_reduce_all(int k, const int *codes, const double *t, const double *rows, long n, int stride, int m,
                     const int *cols, double *out, double *scratch) {
    for (int r = 0; r < k; r++)
        if (cosim_reduce(codes[r], t, rows, n, stride, m, cols, out + (size_t)r * (size_t)m, scratch) != 0) return -1;
    return 0;
}

/* Lock-step rows (cosim/master/native/rows.py, used by cosim/execution/lockstep.py): one FMI call made on the
 * listed instances of K instances of one FMU, rows[0..n) of units[], in a C loop instead of one ctypes call per
 * instance.  The values and their order are those of the Python loop it replaces.  On a status above Warning,
 * or an FMI 3.0 step that ends the simulation or returns early, it stops there and says which row in *fail. */

typedef int (*fmi2_set_real_t)(void *, const unsigned *, size_t, const double *);
typedef int (*fmi3_set_real_t)(void *, const unsigned *, size_t, const double *, size_t);

/* Set the same Real/Float64 variables of each listed row: row r's values start at values + r * stride. */
int cosim_rows_set_reals(const KUnit *units, long n, const int64_t *rows, const unsigned *vrs, size_t n_vrs,
                         size_t n_values, const double *values, long stride, KFail *fail) {
    for (long i = 0; i < n; i++) {
        const int64_t r = rows[i];
        const KUnit *u = &units[r];
        const double *v = values + (size_t)r * (size_t)stride;
        int st = u->version == 2 ? ((fmi2_set_real_t)u->set[0])(u->component, vrs, n_vrs, v)
                                 : ((fmi3_set_real_t)u->set[0])(u->component, vrs, n_vrs, v, n_values);
        if (st > 1) {
            fail->unit = (int)r; fail->call = CALL_SET; fail->type = T_REAL; fail->status = st;
            return RUN_FAILED;
        }
    }
    return RUN_DONE;
}

typedef int (*fmi2_get_real_rows_t)(void *, const unsigned *, size_t, double *);
typedef int (*fmi3_get_real_rows_t)(void *, const unsigned *, size_t, double *, size_t);

/* Get the same Real/Float64 variables of each listed row: row r's values go to out + r * stride. */
int cosim_rows_get_reals(const KUnit *units, long n, const int64_t *rows, const unsigned *vrs, size_t n_vrs,
                         size_t n_values, double *out, long stride, KFail *fail) {
    for (long i = 0; i < n; i++) {
        const int64_t r = rows[i];
        const KUnit *u = &units[r];
        double *v = out + (size_t)r * (size_t)stride;
        int st = u->version == 2 ? ((fmi2_get_real_rows_t)u->get[0])(u->component, vrs, n_vrs, v)
                                 : ((fmi3_get_real_rows_t)u->get[0])(u->component, vrs, n_vrs, v, n_values);
        if (st > 1) {
            fail->unit = (int)r; fail->call = CALL_GET; fail->type = T_REAL; fail->status = st;
            return RUN_FAILED;
        }
    }
    return RUN_DONE;
}

/* doStep(t, h) of each listed row, as the units' do_step calls it (noSetFMUStatePriorToCurrentPoint true). */
int cosim_rows_do_step(const KUnit *units, long n, const int64_t *rows, double t, double h, KFail *fail) {
    fail->t = t;
    fail->h = h;
    for (long i = 0; i < n; i++) {
        const int64_t r = rows[i];
        const KUnit *u = &units[r];
        int st = u->version == 2 ? ((fmi2_do_step_t)u->do_step)(u->component, t, h, 1)
               : ((fmi3_do_step_t)u->do_step)(u->component, t, h, true, u->event, u->terminate, u->early, u->last_time);
        if (st > 1) {
            fail->unit = (int)r; fail->call = CALL_DOSTEP; fail->type = 0; fail->status = st;
            return RUN_FAILED;
        }
        if (u->version == 3 && (*u->terminate || *u->early)) { fail->unit = (int)r; return RUN_ENDED; }
    }
    return RUN_DONE;
}
