/* cosim's native stepping kernel: the fixed-step communication loop of a system of FMI 2.0 / 3.0
 * co-simulation FMUs, in C.  Python (cosim/master/native/binding.py) hands it the FMI functions already
 * resolved from each FMU's library, the instance handles FMPy made, the transfer table and the probe table;
 * it runs up to max_steps communication steps and records the probed columns into a preallocated array.
 *
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
    int version;            /* 2 or 3 */
    void *component;        /* fmi2Component / fmi3Instance */
    void *do_step;
    void *get[3];           /* by type: Real/Float64, Integer/Int32, Boolean */
    void *set[3];
    bool *event, *terminate, *early;  /* FMI 3.0 doStep's out-arguments (the unit's own) */
    double *last_time;
} KUnit;

typedef struct {            /* value references of one type in one unit: one get/set call */
    int unit, type, n;
    const unsigned *vrs;
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

static int get_values(const KUnit *u, const KPort *p, double *out_d, int *scratch_i, bool *scratch_b) {
    int status;
    if (u->version == 2) {
        if (p->type == T_REAL) return ((fmi2_get_real_t)u->get[0])(u->component, p->vrs, (size_t)p->n, out_d);
        status = ((fmi2_get_int_t)u->get[p->type])(u->component, p->vrs, (size_t)p->n, scratch_i);
    } else {
        if (p->type == T_REAL) return ((fmi3_get_real_t)u->get[0])(u->component, p->vrs, (size_t)p->n, out_d, (size_t)p->n);
        if (p->type == T_INT) {
            status = ((fmi3_get_int_t)u->get[1])(u->component, p->vrs, (size_t)p->n, (int32_t *)scratch_i, (size_t)p->n);
        } else {
            status = ((fmi3_get_bool_t)u->get[2])(u->component, p->vrs, (size_t)p->n, scratch_b, (size_t)p->n);
            for (int j = 0; j < p->n; j++) scratch_i[j] = scratch_b[j] ? 1 : 0;
        }
    }
    return status;
}

static int set_ints(const KUnit *u, const KPort *p, const int *values, bool *scratch_b) {
    if (u->version == 2)
        return ((int (*)(void *, const unsigned *, size_t, const int *))u->set[p->type])(u->component, p->vrs, (size_t)p->n, values);
    if (p->type == T_INT)
        return ((int (*)(void *, const unsigned *, size_t, const int32_t *, size_t))u->set[1])(u->component, p->vrs, (size_t)p->n, (const int32_t *)values, (size_t)p->n);
    for (int j = 0; j < p->n; j++) scratch_b[j] = values[j] != 0;
    return ((int (*)(void *, const unsigned *, size_t, const bool *, size_t))u->set[2])(u->component, p->vrs, (size_t)p->n, scratch_b, (size_t)p->n);
}

static int set_reals(const KUnit *u, const KPort *p, const double *values) {
    if (u->version == 2)
        return ((int (*)(void *, const unsigned *, size_t, const double *))u->set[0])(u->component, p->vrs, (size_t)p->n, values);
    return ((int (*)(void *, const unsigned *, size_t, const double *, size_t))u->set[0])(u->component, p->vrs, (size_t)p->n, values, (size_t)p->n);
}

#define FAIL(U, CALL, TYPE, STATUS) do { fail->unit = (U); fail->call = (CALL); fail->type = (TYPE); \
    fail->status = (STATUS); result = RUN_FAILED; goto done; } while (0)

/* Read transfer k's source into its buffers (doubles for Real, ints otherwise); returns the status. */
static int read_transfer(const Kernel *k, const KTransfer *tr, double *d, int *i, bool *b) {
    const KPort *s = &tr->source;
    int status = get_values(&k->units[s->unit], s, d, i, b);
    if (status <= 1 && tr->convert)
        for (int j = 0; j < s->n; j++) { double x = d[j] * tr->factor[j]; d[j] = x + tr->offset[j]; }
    return status;
}

static int write_transfer(const Kernel *k, const KTransfer *tr, const double *d, const int *i, bool *b) {
    const KPort *t = &tr->target;
    if (t->type == T_REAL) return set_reals(&k->units[t->unit], t, d);
    return set_ints(&k->units[t->unit], t, i, b);
}

/* Runs from t0 up to max_steps steps while t < t_end.  rows (max_steps + 1 rows of n_columns) gets the probe
 * at t0 and after each step (NULL: nothing recorded, no stop_when).  Returns RUN_*; *steps_out the steps
 * completed, *t_out the time reached (for RUN_FAILED / RUN_ENDED: the start of the failing step, whose
 * length is fail->h). */
int cosim_kernel_run(const Kernel *k, double t0, double t_end, long max_steps, double *rows, double *times,
                     long *steps_out, double *t_out, KFail *fail) {
    int max_n = 1;
    for (int j = 0; j < k->n_transfers; j++) if (k->transfers[j].source.n > max_n) max_n = k->transfers[j].source.n;
    for (int j = 0; j < k->n_probes; j++) if (k->probes[j].port.n > max_n) max_n = k->probes[j].port.n;
    size_t slots = (size_t)max_n * (size_t)(k->n_transfers + 1);
    double *dbuf = malloc(sizeof(double) * slots);
    int *ibuf = malloc(sizeof(int) * slots);
    bool *bbuf = malloc(sizeof(bool) * (size_t)max_n);
    int result = RUN_DONE;
    long steps = 0;
    double t = t0, h = 0.0;
    fail->unit = -1;
    if (dbuf == NULL || ibuf == NULL || bbuf == NULL) { result = -1; goto done; }
    double *pd = dbuf + (size_t)max_n * (size_t)k->n_transfers;  /* the probe's scratch slot */
    int *pi = ibuf + (size_t)max_n * (size_t)k->n_transfers;

#define PROBE(ROW) do { double *row_ = (ROW); \
        for (int p = 0; p < k->n_probes; p++) { const KProbe *pr = &k->probes[p]; \
            int st = get_values(&k->units[pr->port.unit], &pr->port, pd, pi, bbuf); \
            if (st > 1) FAIL(pr->port.unit, CALL_GET, pr->port.type, st); \
            for (int j = 0; j < pr->port.n; j++) \
                row_[pr->columns[j]] = pr->port.type == T_REAL ? pd[j] : pr->port.type == T_INT ? (double)pi[j] : (pi[j] ? 1.0 : 0.0); \
        } } while (0)

    if (rows != NULL) { times[0] = t0; PROBE(rows); }
    while (t < t_end && steps < max_steps) {
        long kk = (long)nearbyint((t - k->start) / k->step) + 1;
        double t_next = kk >= k->grid_steps ? k->stop : k->start + (double)kk * k->step;
        h = t_next - t;
        if (!k->jacobi) {
            for (int u = 0; u < k->n_units; u++) {
                for (int q = k->plan_start[u]; q < k->plan_start[u + 1]; q++) {
                    const KTransfer *tr = &k->transfers[k->plan[q]];
                    int st = read_transfer(k, tr, dbuf, ibuf, bbuf);
                    if (st > 1) FAIL(tr->source.unit, CALL_GET, tr->source.type, st);
                    st = write_transfer(k, tr, dbuf, ibuf, bbuf);
                    if (st > 1) FAIL(tr->target.unit, CALL_SET, tr->target.type, st);
                }
                const KUnit *un = &k->units[u];
                int st = un->version == 2 ? ((fmi2_do_step_t)un->do_step)(un->component, t, h, 1)
                       : ((fmi3_do_step_t)un->do_step)(un->component, t, h, true, un->event, un->terminate, un->early, un->last_time);
                if (st > 1) FAIL(u, CALL_DOSTEP, 0, st);
                if (un->version == 3 && (*un->terminate || *un->early)) { fail->unit = u; result = RUN_ENDED; goto done; }
            }
        } else {
            for (int u = 0; u < k->n_units; u++) {
                const KUnit *un = &k->units[u];
                int st = un->version == 2 ? ((fmi2_do_step_t)un->do_step)(un->component, t, h, 1)
                       : ((fmi3_do_step_t)un->do_step)(un->component, t, h, true, un->event, un->terminate, un->early, un->last_time);
                if (st > 1) FAIL(u, CALL_DOSTEP, 0, st);
                if (un->version == 3 && (*un->terminate || *un->early)) { fail->unit = u; result = RUN_ENDED; goto done; }
            }
            for (int q = 0; q < k->n_transfers; q++) {  /* every read before any write */
                const KTransfer *tr = &k->transfers[q];
                int st = read_transfer(k, tr, dbuf + (size_t)q * max_n, ibuf + (size_t)q * max_n, bbuf);
                if (st > 1) FAIL(tr->source.unit, CALL_GET, tr->source.type, st);
            }
            for (int q = 0; q < k->n_transfers; q++) {
                const KTransfer *tr = &k->transfers[q];
                int st = write_transfer(k, tr, dbuf + (size_t)q * max_n, ibuf + (size_t)q * max_n, bbuf);
                if (st > 1) FAIL(tr->target.unit, CALL_SET, tr->target.type, st);
            }
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
