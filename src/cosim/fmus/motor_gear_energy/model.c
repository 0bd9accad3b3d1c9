/*
 * motor_gear_energy: electric power and energy of N_TAU (7) BLDC joint motors
 * behind harmonic drives, after thesis section 7.2.2 (eq. 7-10 .. 7-20).
 *
 * Per joint, with the inputs tau [N.m] and omega [rad/s]:
 *   n_motor   = omega * 60/(2 pi) * R                      [rpm]     (7-13)
 *   eta_gear  = table(|n_motor|), linear, constant beyond the ends  (7-14)
 *   motoring  <=> tau * omega >= 0   (standstill under load is motoring:
 *                the motor must produce the torque, so it draws current)
 *   tau_motor = tau / (R eta_gear eta_motor)   if motoring   [N.m]   (7-15)
 *             = tau * eta_gear eta_motor / R   if braking
 *   i_motor   = tau_motor / k_m                            [A]       (7-18)
 *   p_el      = R_T i_motor^2 + tau_motor * omega * R      [W]       (7-19)
 * The mechanical power uses the motor speed in rad/s (omega * R), not eq.
 * 7-16 literally with n in rpm, which would be 60/(2 pi) too large.
 * With recuperation = false the supply takes nothing back: p_el = max(p_el, 0).
 * Energies integrate p_el exactly for inputs held over a step: E += p_el * h.
 */
#include <math.h>

#include "framework.h"

#define N N_TAU
#define NT N_ETA_GEAR_SPEED
#define RAD_PER_S_TO_RPM (60.0 / (2.0 * 3.14159265358979323846))

static Status check_positive(ModelInstance *comp, const char *name, const double *x, int n, bool allow_zero) {
    int i;
    for (i = 0; i < n; i++) {
        if (!isfinite(x[i]) || x[i] < 0.0 || (!allow_zero && x[i] == 0.0)) {
            logError(comp, "parameter %s[%d] = %g must be %s", name, i + 1, x[i],
                     allow_zero ? "finite and >= 0" : "finite and > 0");
            return Error;
        }
    }
    return OK;
}

static Status check_efficiency(ModelInstance *comp, const char *name, const double *x, int n) {
    int i;
    for (i = 0; i < n; i++) {
        if (!(x[i] > 0.0 && x[i] <= 1.0)) {
            logError(comp, "parameter %s[%d] = %g is not an efficiency in (0, 1]", name, i + 1, x[i]);
            return Error;
        }
    }
    return OK;
}

Status model_validate(ModelInstance *comp) {
    const ModelData *d = &comp->d;
    int i;
    if (check_positive(comp, "gear_ratio", d->gear_ratio, N, false) > Warning) return Error;
    if (check_positive(comp, "r_terminal", d->r_terminal, N, true) > Warning) return Error;
    if (check_positive(comp, "k_m", d->k_m, N, false) > Warning) return Error;
    if (check_efficiency(comp, "eta_motor", d->eta_motor, N) > Warning) return Error;
    if (check_efficiency(comp, "eta_gear_value", d->eta_gear_value, NT) > Warning) return Error;
    for (i = 0; i < NT; i++) {
        if (!isfinite(d->eta_gear_speed[i]) || (i > 0 && !(d->eta_gear_speed[i] > d->eta_gear_speed[i - 1]))) {
            logError(comp, "parameter eta_gear_speed must be finite and strictly increasing, but eta_gear_speed[%d] = %g", i + 1,
                     d->eta_gear_speed[i]);
            return Error;
        }
    }
    return OK;
}

void model_initialize(ModelInstance *comp) {
    int j;
    for (j = 0; j < N; j++) comp->d.e_el[j] = 0.0;
    comp->d.e_total = 0.0;
    comp->d.e_total_no_recuperation = 0.0;
}

/* Gear efficiency at motor speed |n| [rpm]: linear in the table, constant beyond its ends. */
static double gear_efficiency(const ModelData *d, double n) {
    const double *s = d->eta_gear_speed, *v = d->eta_gear_value;
    double a = fabs(n);
    int i;
    if (a <= s[0]) return v[0];
    for (i = 0; i + 1 < NT; i++) {
        if (a < s[i + 1]) return v[i] + (v[i + 1] - v[i]) * (a - s[i]) / (s[i + 1] - s[i]);
    }
    return v[NT - 1];
}

Status model_calculate(ModelInstance *comp) {
    ModelData *d = &comp->d;
    double total = 0.0;
    int j;
    for (j = 0; j < N; j++) {
        if (check_finite(comp, "tau", j, d->tau[j]) > Warning) return Error;
        if (check_finite(comp, "omega", j, d->omega[j]) > Warning) return Error;
    }
    for (j = 0; j < N; j++) {
        const double tau = d->tau[j], omega = d->omega[j], ratio = d->gear_ratio[j];
        const double omega_motor = omega * ratio; /* rad/s */
        double eta, p;
        d->n_motor[j] = omega_motor * RAD_PER_S_TO_RPM;
        d->eta_gear[j] = gear_efficiency(d, d->n_motor[j]);
        eta = d->eta_gear[j] * d->eta_motor[j];
        /* Braking only when torque and speed oppose; standstill under load is motoring. */
        d->tau_motor[j] = tau * omega < 0.0 ? tau * eta / ratio : tau / (ratio * eta);
        d->i_motor[j] = d->tau_motor[j] / d->k_m[j];
        p = d->r_terminal[j] * d->i_motor[j] * d->i_motor[j] + d->tau_motor[j] * omega_motor;
        d->p_el[j] = (!d->recuperation && p < 0.0) ? 0.0 : p;
        total += d->p_el[j];
    }
    d->p_total = total;
    return OK;
}

Status model_do_step(ModelInstance *comp, double t, double h) {
    ModelData *d = &comp->d;
    double total = 0.0, drawn = 0.0;
    int j;
    (void)t;
    if (model_calculate(comp) > Warning) return Error;
    for (j = 0; j < N; j++) {
        d->e_el[j] += d->p_el[j] * h;
        total += d->e_el[j];
        drawn += d->p_el[j] > 0.0 ? d->p_el[j] : 0.0;
    }
    d->e_total = total;
    d->e_total_no_recuperation += drawn * h;
    return OK;
}
