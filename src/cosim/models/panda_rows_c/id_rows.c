/* The per-step arithmetic of the inverse-dynamics level's lock-step twins for K rows in one call:
 * the trajectory generator's sampling (models/trajectory.py, TrajectoryGeneratorBatch) and the arm's outputs
 * after pinocchio's RNEA and kinematics (models/panda_inverse_dynamics.py, PandaInverseDynamicsBatch).
 *
 * Every value is computed with the operations of the numpy code it replaces, in the same order, and the
 * library is compiled with -ffp-contract=off (no fused multiply-add), so the rows are those of the single
 * units bit for bit (tests/test_lockstep.py compares them).  models/panda_rows.py compiles this file into the
 * row kernels' library at first use and calls it through ctypes; every array is C-ordered float64 (flags: one
 * byte per row), row k at offset k * (its row length). */

#include <math.h>
#include <stdint.h>

#define N 7 /* joints */

/* The planned parabolic blends of K rows, padded to the same number of phases (padding starts at +inf). */
typedef struct {
    int64_t rows, phases;
    const double *starts;             /* K x P phase start times */
    const double *q, *v, *a;          /* K x P x 7: position, velocity, acceleration at each phase's start */
    const double *first, *last;       /* K x 7: the first and last waypoint (rest before / after) */
    const double *duration;           /* K */
} TrajRows;

/* ParabolicBlendTrajectory.sample of every row at time t: q, v, a (K x 7 each; any may be NULL). */
void traj_rows_sample(const TrajRows *p, double t, double *q, double *v, double *a)
{
    for (int64_t r = 0; r < p->rows; r++) {
        double *qr = q ? q + N * r : 0, *vr = v ? v + N * r : 0, *ar = a ? a + N * r : 0;
        const double *rest = t <= 0.0 ? p->first + N * r : t >= p->duration[r] ? p->last + N * r : 0;
        if (rest) {
            for (int j = 0; j < N; j++) {
                if (qr) qr[j] = rest[j];
                if (vr) vr[j] = 0.0;
                if (ar) ar[j] = 0.0;
            }
            continue;
        }
        const double *starts = p->starts + p->phases * r;
        int64_t count = 0; /* bisect_right(starts, t): the phases started by t (the padding never starts) */
        for (int64_t i = 0; i < p->phases; i++) count += starts[i] <= t;
        const int64_t k = count > 0 ? count - 1 : 0;
        const double dt = t - starts[k];
        const int64_t at = N * (p->phases * r + k);
        const double *q0 = p->q + at, *v0 = p->v + at, *a0 = p->a + at;
        for (int j = 0; j < N; j++) {
            /* numpy: v0 + a * dt and q0 + v0 * dt + 0.5 * a * dt * dt, left to right */
            if (vr) vr[j] = v0[j] + a0[j] * dt;
            if (qr) qr[j] = (q0[j] + v0[j] * dt) + ((0.5 * a0[j]) * dt) * dt;
            if (ar) ar[j] = a0[j];
        }
    }
}

/* numpy's max / min of n values: NaN if any is NaN */
static double nan_max(const double *x, int n)
{
    double m = x[0];
    for (int j = 0; j < n; j++) {
        if (isnan(x[j])) return x[j];
        if (x[j] > m) m = x[j];
    }
    return m;
}

static double nan_min(const double *x, int n)
{
    double m = x[0];
    for (int j = 0; j < n; j++) {
        if (isnan(x[j])) return x[j];
        if (x[j] < m) m = x[j];
    }
    return m;
}

/* The arm's state and outputs; done_* is the TCP path committed at the last communication point. */
typedef struct {
    int64_t rows;
    const double *q, *qd, *tau;                    /* K x 7 */
    const double *q_min, *q_max, *qd_max, *tau_max; /* K x 7 limits */
    const double *ee_pos;                          /* K x 3 */
    const double *done_length, *done_ee;           /* K, K x 3 */
    double *ee_path_length;                        /* K */
    double *tracking_error;                        /* K */
    double *tau_ratio;                             /* K x 7 */
    uint8_t *limit_violated;                       /* K */
} IdRows;

/* After pinocchio has written tau and ee_pos: the path length of the n listed rows (when chord is set: the
 * chord from the committed point added), and for every row the tracking error (0: ideal tracking), the
 * torque ratios and the limit flag, as PandaInverseDynamicsBatch.compute_outputs computes them. */
void id_rows_outputs(const IdRows *p, int64_t n, const int64_t *rows, int chord)
{
    if (chord) {
        for (int64_t i = 0; i < n; i++) {
            const int64_t k = rows[i];
            const double *ee = p->ee_pos + 3 * k, *last = p->done_ee + 3 * k;
            const double dx = ee[0] - last[0], dy = ee[1] - last[1], dz = ee[2] - last[2];
            p->ee_path_length[k] = p->done_length[k] + sqrt((dx * dx + dy * dy) + dz * dz);
        }
    }
    for (int64_t k = 0; k < p->rows; k++) {
        const double *q = p->q + N * k, *qd = p->qd + N * k, *tau = p->tau + N * k;
        const double *q_min = p->q_min + N * k, *q_max = p->q_max + N * k, *qd_max = p->qd_max + N * k;
        const double *tau_max = p->tau_max + N * k;
        double *ratio = p->tau_ratio + N * k;
        double below[N], above[N], fast[N];
        for (int j = 0; j < N; j++) {
            ratio[j] = fabs(tau[j]) / tau_max[j];
            below[j] = q[j] - q_min[j];
            above[j] = q_max[j] - q[j];
            fast[j] = fabs(qd[j]) - qd_max[j];
        }
        p->tracking_error[k] = 0.0;
        /* numpy: ratio.max > 1 | (q - q_min).min < 0 | (q_max - q).min < 0 | (|qd| - qd_max).max > 0 */
        p->limit_violated[k] = (uint8_t)(nan_max(ratio, N) > 1.0 || nan_min(below, N) < 0.0
                                         || nan_min(above, N) < 0.0 || nan_max(fast, N) > 0.0);
    }
}
