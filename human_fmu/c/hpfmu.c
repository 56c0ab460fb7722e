/*
 * hpfmu.c: FMI 2.0 co-simulation interface of the hpcosim human side.
 *
 * The plant (12-DOF hybrid human-prosthesis model) and the human-side controller (feedback
 * linearization of the human outputs) are CasADi-generated C (hpfmu_casadi.inc, included
 * below); this file is the hybrid integration algorithm of hp_model/simulator.py
 * (HybridSimulator.run, mode "human") and the FMI 2.0 API around it:
 *
 *   doStep(t, H): the inputs (prosthesis motor torques) are held over the step;
 *     - friction-cone check with the new inputs (fall after cone_periods bad steps);
 *     - `substeps` RK4 steps of h = H / substeps (rk4_human_<d>); a step ending with the
 *       swing sole below ground while tau >= guard_tau_min is cut at the crossing (Illinois
 *       method on s in (0, 1], one RK4 step of length s h per iteration, |z| <= event_tol or
 *       event_iters iterations); the landing foot is rotated flat about its ankle; the impact
 *       map of the next domain gives qd+; the rest (1 - s) h is integrated in the new domain;
 *     - state checks at the end (non-finite, speed, hip height, tau backward, tau_max, stall) and the
 *       touchdown-pitch check; a fall ends the walk: the `fall` output is raised, doStep
 *       returns fmi2Discard (then and on every later call), fmi2GetBooleanStatus
 *       (fmi2Terminated) is true and fmi2GetRealStatus(fmi2LastSuccessfulTime) is the time
 *       of the state held: the end of the step, or its start when the step ended non-finite
 *       or blown up (codes 1, 8) or the friction cone ended it before integrating (code 5),
 *       so every output stays finite and physical.
 *
 * No global mutable state: any number of instances may live in one process.
 *
 * Rebuild (Linux, any C99 compiler), from the FMU's sources/ folder:
 *   cc -shared -fPIC -O2 -fno-math-errno -ffp-contract=off -fvisibility=hidden \
 *      -I. hpfmu.c -o hpcosim_human.so -lm
 */

#include <math.h>
#include <stdint.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

/* the generated functions are private to this translation unit */
#define CASADI_SYMBOL_EXPORT static
#include "hpfmu_casadi.inc"
#include "hpfmu_config.h"

#define NQ HPFMU_NQ
#define NX (2 * HPFMU_NQ)
#define NTH HPFMU_NTHETA
#define PS 0
#define PNS 1

typedef int (*cs_eval)(const casadi_real **, casadi_real **, casadi_int *, casadi_real *, int);
typedef int (*cs_work)(casadi_int *, casadi_int *, casadi_int *, casadi_int *);

enum { F_RK4, F_XDOT = 2, F_IMPACT = 4, F_GUARD = 6, F_FRAMES = 8, N_FN = 9 };
static const cs_eval FN[N_FN] = {
    rk4_human_ps, rk4_human_pns, xdot_human_ps, xdot_human_pns,
    impact_ps, impact_pns, guard_ps, guard_pns, frames};
static const cs_work FN_WORK[N_FN] = {
    rk4_human_ps_work, rk4_human_pns_work, xdot_human_ps_work, xdot_human_pns_work,
    impact_ps_work, impact_pns_work, guard_ps_work, guard_pns_work, frames_work};

enum { MODE_INSTANTIATED, MODE_INIT, MODE_STEP, MODE_TERMINATED, MODE_ERROR };

/* everything that fmi2GetFMUstate copies */
typedef struct {
    int mode;
    double r[HPFMU_N_REAL];
    int i[HPFMU_N_INTEGER];
    int b[HPFMU_N_BOOLEAN];
    /* hybrid state and the integration settings fixed at initialization */
    double x[NX];
    int d;
    double time;
    double z_prev;   /* swing height at the end of the last accepted RK4 step */
    double tau_peak;
    int bad_cone;
    int steps;
    int failed;
    int fall_code;
    int torque_clamped; /* torque inputs set outside HPFMU_TORQUE_LIMIT */
    int heel;        /* a touchdown with too much foot pitch happened in this step */
    double t_impact;
    double t_step;   /* start of the current step: the start time, then the last impact */
    double theta[2][NTH];
    double gains[3];
    double up[2];
    int substeps, event_iters, cone_periods;
    double guard_tau_min, event_tol, min_hip_height, tau_backward, tau_max, max_step_time,
        max_speed, min_normal_force, mu, max_touchdown_pitch;
    int outputs_valid;
} Data;

typedef struct {
    Data s;
    char *name;
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment env;
    int logging_on;
    const casadi_real **arg;
    casadi_real **res;
    casadi_int *iw;
    casadi_real *w;
    /* last evaluation of the vector field (outputs) */
    double xdot[NX], u[HPFMU_NU], lam[HPFMU_NLAM];
} Inst;

/* -- logging ------------------------------------------------------------------------------ */
static void logmsg(Inst *c, fmi2Status st, const char *cat, const char *fmt, ...) {
    char buf[1024];
    va_list ap;
    size_t k;
    if (c == NULL || c->logger == NULL) return;
    if (st == fmi2OK && !c->logging_on) return;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    for (k = 0; buf[k]; k++)  /* the message may be used as a format string by the master */
        if (buf[k] == '%') buf[k] = ' ';
    c->logger(c->env, c->name ? c->name : "hpcosim_human", st, cat, buf);
}

static fmi2Status fail(Inst *c, const char *fmt, const char *what) {
    logmsg(c, fmi2Error, "logStatusError", fmt, what);
    return fmi2Error;
}

/* -- the generated functions --------------------------------------------------------------- */
static int call(Inst *c, int f, const double **in, int n_in, double **out, int n_out) {
    int k;
    for (k = 0; k < n_in; k++) c->arg[k] = in[k];
    for (k = 0; k < n_out; k++) c->res[k] = out[k];
    return FN[f](c->arg, c->res, c->iw, c->w, 0);
}

/* one RK4 step of the closed loop (rk4_human_<d>); returns the swing-sole height at the end */
static double rk4(Inst *c, int d, const double *x, double h, double *xn) {
    double z = 0.0;
    const double *in[5];
    double *out[2];
    in[0] = x; in[1] = c->s.theta[d]; in[2] = c->s.gains; in[3] = c->s.up; in[4] = &h;
    out[0] = xn; out[1] = &z;
    call(c, F_RK4 + d, in, 5, out, 2);
    return z;
}

/* the vector field at the current state and inputs: xdot, u (6), lam (6) */
static void eval_field(Inst *c) {
    const double *in[4];
    double *out[3];
    in[0] = c->s.x; in[1] = c->s.theta[c->s.d]; in[2] = c->s.gains; in[3] = c->s.up;
    out[0] = c->xdot; out[1] = c->u; out[2] = c->lam;
    call(c, F_XDOT + c->s.d, in, 4, out, 3);
}

static double guard(Inst *c, int d, const double *q, const double *qd) {
    double z = 0.0, vz = 0.0;
    const double *in[2];
    double *out[2];
    in[0] = q; in[1] = qd; out[0] = &z; out[1] = &vz;
    call(c, F_GUARD + d, in, 2, out, 2);
    return z;
}

static void frame_poses(Inst *c, const double *q, double *pose) {
    double zero[NQ], vel[3 * HPFMU_NFRAMES];
    const double *in[2];
    double *out[2];
    memset(zero, 0, sizeof zero);
    in[0] = q; in[1] = zero; out[0] = pose; out[1] = vel;
    call(c, F_FRAMES, in, 2, out, 2);
}

static void impact(Inst *c, int into, const double *q, const double *qd_minus, double *qd_plus) {
    double imp[HPFMU_NLAM];
    const double *in[2];
    double *out[2];
    in[0] = q; in[1] = qd_minus; out[0] = qd_plus; out[1] = imp;
    call(c, F_IMPACT + into, in, 2, out, 2);
}

/* tau = (c_row . q - p_min) / (p_max - p_min) */
static double phase(const Inst *c, int d, const double *q) {
    double s = 0.0;
    int k;
    const double *th = c->s.theta[d];
    for (k = 0; k < NQ; k++) s += HPFMU_PHASE_ROW[d][k] * q[k];
    return (s - th[NTH - 2]) / (th[NTH - 1] - th[NTH - 2]);
}

/* rotate the foot that becomes the stance foot of `into` flat about its ankle; the pitch */
static double flatten_landing_foot(Inst *c, int into, double *q) {
    double pose[3 * HPFMU_NFRAMES];
    double pitch;
    frame_poses(c, q, pose);
    pitch = pose[3 * HPFMU_STANCE_FRAME[into] + 2];
    q[HPFMU_LANDING_ANKLE[into]] -= pitch;
    return pitch;
}

/* s in (0, 1] with the swing height of rk4(x0, s h) = 0 (Illinois); xs = that state */
static double locate(Inst *c, int d, const double *x0, double h, double z0, double z1,
                     double *xs) {
    double a = 0.0, b = 1.0, fa = z0, fb = z1, s = 1.0, z;
    int side = 0, k;
    for (k = 0; k < c->s.event_iters; k++) {
        s = (a * fb - b * fa) / (fb - fa);
        z = rk4(c, d, x0, s * h, xs);
        if (fabs(z) <= c->s.event_tol) break;
        if (z > 0) {
            a = s; fa = z;
            if (side == 1) fb /= 2;
            side = 1;
        } else {
            b = s; fb = z;
            if (side == -1) fa /= 2;
            side = -1;
        }
    }
    return s;
}

static const char *fall_reason(int code) {
    switch (code) {
    case 1: return "non-finite state";
    case 2: return "hip height below min_hip_height";
    case 3: return "phase ran backward";
    case 4: return "no touchdown by tau_max";
    case 5: return "stance foot left the friction cone";
    case 6: return "landed on heel or toe";
    case 7: return "phase stalled";
    case 8: return "state diverged";
    default: return "none";
    }
}

/* a prosthesis torque input bounded to the device's limit (counted when it had to be); a
   non-finite value is kept, and fmi2DoStep refuses it */
static double bounded_torque(Data *s, int k, double v) {
    const double lim = HPFMU_TORQUE_LIMIT[k];
    if (!isfinite(v)) return v;
    if (v > lim || v < -lim) {
        s->torque_clamped++;
        return v > lim ? lim : -lim;
    }
    return v;
}

static void set_fall(Inst *c, int code) {
    Data *s = &c->s;
    s->failed = 1;
    s->fall_code = code;
    s->outputs_valid = 0;
    logmsg(c, fmi2Warning, "logEvents",
           "fall at t = %.6f s in %s (code %d: %s); the state is frozen", s->time,
           HPFMU_DOMAIN_NAME[s->d], code, fall_reason(code));
}

/* state checks of HybridSimulator (done at the end of a step = start of the next period) */
static void state_checks(Inst *c) {
    Data *s = &c->s;
    double tau = phase(c, s->d, s->x);
    int k, finite = 1, fast = 0, code = 0;
    if (tau > s->tau_peak) s->tau_peak = tau;
    for (k = 0; k < NX; k++)
        if (!isfinite(s->x[k])) finite = 0;
    for (k = NQ; k < NX; k++)
        if (fabs(s->x[k]) > s->max_speed) fast = 1;
    if (!finite) code = 1;
    else if (fast) code = 8;
    else if (s->x[HPFMU_IDX_ZB] < s->min_hip_height) code = 2;
    else if (tau < s->tau_peak - s->tau_backward) code = 3;
    else if (tau > s->tau_max) code = 4;
    else if (s->time - s->t_step > s->max_step_time) code = 7;
    else if (s->heel) code = 6;
    if (code) set_fall(c, code);
}

/* one communication step: HybridSimulator.run's period loop body */
static void integrate(Inst *c, double t0, double H) {
    Data *s = &c->s;
    const double h = H / s->substeps;
    double xn[NX], xe[NX], qe[NQ], qdp[NQ];
    int j;
    for (j = 0; j < s->substeps; j++) {
        double rest = h;
        while (rest > 0) {
            double z = rk4(c, s->d, s->x, rest, xn);
            int armed = phase(c, s->d, s->x) >= s->guard_tau_min;
            if (armed && s->z_prev > 0 && z <= 0) {
                double sl = locate(c, s->d, s->x, rest, s->z_prev, z, xe);
                int nxt = HPFMU_NEXT[s->d];
                double pitch;
                memcpy(qe, xe, sizeof qe);
                pitch = flatten_landing_foot(c, nxt, qe);
                impact(c, nxt, qe, xe + NQ, qdp);
                s->t_impact = t0 + j * h + (h - rest) + sl * rest;
                s->t_step = s->t_impact;
                s->steps += 1;
                logmsg(c, fmi2OK, "logEvents",
                       "impact %d at t = %.9f s into %s (foot pitch removed %.3g rad)",
                       s->steps, s->t_impact, HPFMU_DOMAIN_NAME[nxt], pitch);
                if (fabs(pitch) > s->max_touchdown_pitch) s->heel = 1;
                memcpy(s->x, qe, sizeof qe);
                memcpy(s->x + NQ, qdp, sizeof qdp);
                s->d = nxt;
                s->z_prev = guard(c, nxt, qe, qdp);
                s->tau_peak = -INFINITY;
                rest -= sl * rest;
                if (rest <= 1e-15 * h) break;
                continue;
            }
            memcpy(s->x, xn, sizeof xn);
            s->z_prev = z;
            rest = 0.0;
        }
    }
}

/* -- outputs --------------------------------------------------------------------------------- */
static void update_outputs(Inst *c) {
    Data *s = &c->s;
    int k;
    if (s->outputs_valid) return;
    eval_field(c);
    s->r[VR_KNEE_ANGLE] = s->x[HPFMU_IDX_PK];
    s->r[VR_ANKLE_ANGLE] = s->x[HPFMU_IDX_PA];
    s->r[VR_KNEE_VELOCITY] = s->x[NQ + HPFMU_IDX_PK];
    s->r[VR_ANKLE_VELOCITY] = s->x[NQ + HPFMU_IDX_PA];
    s->r[VR_FOOT_LOAD] = s->d == PS ? c->lam[1] : 0.0;
    s->b[VR_FOOT_CONTACT] = s->d == PS;
    s->r[VR_SOCKET_PITCH] = 0.0;
    for (k = 0; k < NQ; k++) s->r[VR_SOCKET_PITCH] += HPFMU_SOCKET_PITCH_ROW[k] * s->x[k];
    s->r[VR_STANCE_FX] = c->lam[0];
    s->r[VR_STANCE_FZ] = c->lam[1];
    s->r[VR_STANCE_MY] = c->lam[2];
    s->r[VR_SOCKET_FX] = c->lam[3];
    s->r[VR_SOCKET_FZ] = c->lam[4];
    s->r[VR_SOCKET_MY] = c->lam[5];
    for (k = 0; k < NQ; k++) {
        s->r[VR_Q_1 + k] = s->x[k];
        s->r[VR_QD_1 + k] = s->x[NQ + k];
    }
    for (k = 0; k < HPFMU_NU; k++) s->r[VR_U_1 + k] = c->u[k];
    s->r[VR_TAU] = phase(c, s->d, s->x);
    s->r[VR_T_IMPACT] = s->t_impact;
    s->i[VR_DOMAIN] = s->d;
    s->i[VR_STEPS] = s->steps;
    s->i[VR_FALL_CODE] = s->fall_code;
    s->i[VR_TORQUE_CLAMPED] = s->torque_clamped;
    s->b[VR_FALL] = s->failed;
    s->outputs_valid = 1;
}

/* -- initialization ------------------------------------------------------------------------- */
static uint64_t splitmix64(uint64_t seed, uint64_t k) {
    uint64_t z = seed + (k + 1) * UINT64_C(0x9E3779B97F4A7C15);
    z = (z ^ (z >> 30)) * UINT64_C(0xBF58476D1CE4E5B9);
    z = (z ^ (z >> 27)) * UINT64_C(0x94D049BB133111EB);
    return z ^ (z >> 31);
}

/* validate the parameters and set up the hybrid state; fmi2Error (logged) if invalid */
static fmi2Status setup(Inst *c) {
    Data *s = &c->s;
    const double *r = s->r;
    double q[NQ], qd[NQ], amp;
    uint64_t seed;
    int k, d;
    for (k = 0; k < HPFMU_N_REAL; k++)
        if (HPFMU_REAL_KIND[k] == 'p' && !isfinite(r[k]))
            return fail(c, "parameter %s is not finite", HPFMU_REAL_NAME[k]);
    if (s->i[VR_SUBSTEPS] < 1) return fail(c, "parameter %s must be >= 1", "substeps");
    if (s->i[VR_EVENT_ITERS] < 1) return fail(c, "parameter %s must be >= 1", "event_iters");
    if (s->i[VR_CONE_PERIODS] < 1) return fail(c, "parameter %s must be >= 1", "cone_periods");
    if (s->i[VR_INITIAL_DOMAIN] != PS && s->i[VR_INITIAL_DOMAIN] != PNS)
        return fail(c, "parameter %s must be 0 (ps) or 1 (pns)", "initial_domain");
    if (!(r[VR_EVENT_TOL] > 0)) return fail(c, "parameter %s must be > 0", "event_tol");
    if (!(r[VR_HUMAN_PERTURBATION] >= 0))
        return fail(c, "parameter %s must be >= 0", "human_perturbation");
    if (!(r[VR_MU] >= 0)) return fail(c, "parameter %s must be >= 0", "mu");
    if (!(r[VR_MAX_TOUCHDOWN_PITCH] > 0))
        return fail(c, "parameter %s must be > 0", "max_touchdown_pitch");
    if (!(r[VR_TAU_BACKWARD] > 0)) return fail(c, "parameter %s must be > 0", "tau_backward");
    if (!(r[VR_MAX_STEP_TIME] > 0)) return fail(c, "parameter %s must be > 0", "max_step_time");
    if (!(r[VR_MAX_SPEED] > 0)) return fail(c, "parameter %s must be > 0", "max_speed");
    if (!(r[VR_FL_EPS] >= 0 && r[VR_FL_KP] >= 0 && r[VR_FL_KD] >= 0))
        return fail(c, "parameter %s must be >= 0", "fl_eps, fl_kp, fl_kd");
    for (d = 0; d < 2; d++) {
        const double *th = r + (d == PS ? VR_THETA_PS_1 : VR_THETA_PNS_1);
        if (!(th[NTH - 1] > th[NTH - 2]))
            return fail(c, "gait parameters of %s: p_max must exceed p_min",
                        HPFMU_DOMAIN_NAME[d]);
        if (!(th[NTH - 3] > 0))
            return fail(c, "gait parameters of %s: v_hip must be > 0", HPFMU_DOMAIN_NAME[d]);
    }
    for (k = 0; k < 3; k++)
        if (fabs(r[VR_Q0_1 + HPFMU_SOCKET_FIRST + k]) > 1e-6)
            return fail(c, "initial state: %s (the socket's fixed joint) must be 0",
                        HPFMU_REAL_NAME[VR_Q0_1 + HPFMU_SOCKET_FIRST + k]);

    /* the gait the human tracks: nominal + the deterministic perturbation */
    amp = r[VR_HUMAN_PERTURBATION];
    seed = (uint64_t)(int64_t)s->i[VR_HUMAN_SEED];
    for (d = 0; d < 2; d++) {
        const double *th = r + (d == PS ? VR_THETA_PS_1 : VR_THETA_PNS_1);
        for (k = 0; k < NTH; k++) s->theta[d][k] = th[k];
        if (amp != 0.0)
            for (k = 0; k < HPFMU_NALPHA; k++) {
                double u01 = (double)(splitmix64(seed, (uint64_t)(d * HPFMU_NALPHA + k)) >> 11)
                             * 0x1.0p-53;
                s->theta[d][k] = s->theta[d][k] + amp * (2.0 * u01 - 1.0);
            }
    }
    s->gains[0] = r[VR_FL_EPS]; s->gains[1] = r[VR_FL_KP]; s->gains[2] = r[VR_FL_KD];
    s->substeps = s->i[VR_SUBSTEPS];
    s->event_iters = s->i[VR_EVENT_ITERS];
    s->cone_periods = s->i[VR_CONE_PERIODS];
    s->guard_tau_min = r[VR_GUARD_TAU_MIN];
    s->event_tol = r[VR_EVENT_TOL];
    s->min_hip_height = r[VR_MIN_HIP_HEIGHT];
    s->tau_backward = r[VR_TAU_BACKWARD];
    s->tau_max = r[VR_TAU_MAX];
    s->max_step_time = r[VR_MAX_STEP_TIME];
    s->max_speed = r[VR_MAX_SPEED];
    s->min_normal_force = r[VR_MIN_NORMAL_FORCE];
    s->mu = r[VR_MU];
    s->max_touchdown_pitch = r[VR_MAX_TOUCHDOWN_PITCH];

    /* initial state (see human_fmu/initial.py) */
    d = s->i[VR_INITIAL_DOMAIN];
    for (k = 0; k < NQ; k++) { q[k] = r[VR_Q0_1 + k]; qd[k] = r[VR_QD0_1 + k]; }
    if (r[VR_OFFSET_KNEE] != 0.0 || r[VR_OFFSET_ANKLE] != 0.0) {
        q[HPFMU_IDX_PK] += r[VR_OFFSET_KNEE];
        q[HPFMU_IDX_PA] += r[VR_OFFSET_ANKLE];
        if (d == PS) {
            double pose[3 * HPFMU_NFRAMES], x_f, z_f, qd_proj[NQ];
            const int i = HPFMU_STANCE_FRAME[PS];
            frame_poses(c, r + VR_Q0_1, pose);
            x_f = pose[3 * i]; z_f = pose[3 * i + 1];
            q[0] = q[1] = q[2] = 0.0;
            frame_poses(c, q, pose);
            q[2] = -pose[3 * i + 2];
            frame_poses(c, q, pose);
            q[0] = x_f - pose[3 * i];
            q[1] = z_f - pose[3 * i + 1];
            impact(c, PS, q, qd, qd_proj);
            memcpy(qd, qd_proj, sizeof qd);
        }
    }
    {   /* the stance foot of the initial domain must be flat on the ground */
        double pose[3 * HPFMU_NFRAMES];
        const int i = HPFMU_STANCE_FRAME[d];
        frame_poses(c, q, pose);
        if (fabs(pose[3 * i + 1]) > 1e-3 || fabs(pose[3 * i + 2]) > 1e-3) {
            logmsg(c, fmi2Error, "logStatusError",
                   "initial state: the %s stance foot is not flat on the ground (height %.4g m, "
                   "pitch %.4g rad)", HPFMU_DOMAIN_NAME[d], pose[3 * i + 1], pose[3 * i + 2]);
            return fmi2Error;
        }
    }
    for (k = 0; k < NQ; k++) { s->x[k] = q[k]; s->x[NQ + k] = qd[k]; }
    s->d = d;
    s->torque_clamped = 0;
    s->up[0] = bounded_torque(s, 0, r[VR_U_KNEE]);
    s->up[1] = bounded_torque(s, 1, r[VR_U_ANKLE]);
    s->z_prev = guard(c, d, q, qd);
    s->tau_peak = -INFINITY;
    s->bad_cone = 0;
    s->steps = 0;
    s->failed = 0;
    s->fall_code = 0;
    s->heel = 0;
    s->t_impact = -1.0;
    s->t_step = s->time;  /* the experiment's start time (fmi2SetupExperiment) */
    s->outputs_valid = 0;
    return fmi2OK;
}

static void set_defaults(Data *s) {
    memset(s, 0, sizeof *s);
    memcpy(s->r, HPFMU_REAL_START, sizeof s->r);
    memcpy(s->i, HPFMU_INTEGER_START, sizeof s->i);
    memcpy(s->b, HPFMU_BOOLEAN_START, sizeof s->b);
    s->mode = MODE_INSTANTIATED;
    s->t_impact = -1.0;
}

/* -- FMI 2.0 API ---------------------------------------------------------------------------- */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

static void *xalloc(size_t n, size_t size) { return calloc(n == 0 ? 1 : n, size); }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    Inst *c;
    casadi_int n_arg = 0, n_res = 0, n_iw = 0, n_w = 0;
    int f;
    (void)fmuResourceLocation;
    (void)visible;
    if (functions == NULL || functions->logger == NULL) return NULL;
    if (fmuType != fmi2CoSimulation) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError", "hpcosim_human supports co-simulation only");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, HPFMU_GUID) != 0) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError",
                          "GUID mismatch: the binary does not belong to this modelDescription");
        return NULL;
    }
    c = (Inst *)xalloc(1, sizeof(Inst));
    if (c == NULL) return NULL;
    c->logger = functions->logger;
    c->env = functions->componentEnvironment;
    c->logging_on = loggingOn ? 1 : 0;
    c->name = (char *)xalloc(strlen(instanceName ? instanceName : "") + 1, 1);
    if (c->name) strcpy(c->name, instanceName ? instanceName : "");
    for (f = 0; f < N_FN; f++) {
        casadi_int a, r, iw, w;
        FN_WORK[f](&a, &r, &iw, &w);
        if (a > n_arg) n_arg = a;
        if (r > n_res) n_res = r;
        if (iw > n_iw) n_iw = iw;
        if (w > n_w) n_w = w;
    }
    c->arg = (const casadi_real **)xalloc((size_t)n_arg, sizeof(casadi_real *));
    c->res = (casadi_real **)xalloc((size_t)n_res, sizeof(casadi_real *));
    c->iw = (casadi_int *)xalloc((size_t)n_iw, sizeof(casadi_int));
    c->w = (casadi_real *)xalloc((size_t)n_w, sizeof(casadi_real));
    if (!c->name || !c->arg || !c->res || !c->iw || !c->w) {
        free(c->name); free((void *)c->arg); free(c->res); free(c->iw); free(c->w); free(c);
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError", "out of memory");
        return NULL;
    }
    set_defaults(&c->s);
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return;
    free(c->name);
    free((void *)c->arg);
    free(c->res);
    free(c->iw);
    free(c->w);
    free(c);
}

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    Inst *c = (Inst *)comp;
    (void)nCategories;
    (void)categories;
    if (c == NULL) return fmi2Error;
    c->logging_on = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Inst *c = (Inst *)comp;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (c == NULL) return fmi2Error;
    if (c->s.mode != MODE_INSTANTIATED) return fail(c, "%s: not in instantiated mode",
                                                    "fmi2SetupExperiment");
    c->s.time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    if (c->s.mode != MODE_INSTANTIATED)
        return fail(c, "%s: not in instantiated mode", "fmi2EnterInitializationMode");
    c->s.mode = MODE_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    if (c->s.mode != MODE_INIT)
        return fail(c, "%s: not in initialization mode", "fmi2ExitInitializationMode");
    if (setup(c) != fmi2OK) {
        c->s.mode = MODE_ERROR;
        return fmi2Error;
    }
    state_checks(c);  /* HybridSimulator checks the initial state too */
    c->s.mode = MODE_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    c->s.mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    set_defaults(&c->s);
    return fmi2OK;
}

/* -- get/set ---------------------------------------------------------------------------------- */
static int can_get(Inst *c) { return c->s.mode == MODE_INIT || c->s.mode == MODE_STEP ||
                                     c->s.mode == MODE_TERMINATED; }

static fmi2Status prepare_outputs(Inst *c) {
    if (c->s.mode == MODE_INIT) {  /* initial unknowns: evaluate at the initial state */
        if (setup(c) != fmi2OK) return fmi2Error;
    }
    update_outputs(c);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    int need = 0;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_REAL) return fail(c, "fmi2GetReal: %s", "unknown value reference");
        if (HPFMU_REAL_KIND[vr[k]] == 'o') need = 1;
    }
    if (need) {
        if (!can_get(c)) return fail(c, "fmi2GetReal: %s", "outputs need initialization mode");
        if (prepare_outputs(c) != fmi2OK) return fmi2Error;
    }
    for (k = 0; k < nvr; k++) value[k] = c->s.r[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    int need = 0;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_INTEGER)
            return fail(c, "fmi2GetInteger: %s", "unknown value reference");
        if (HPFMU_INTEGER_KIND[vr[k]] == 'o') need = 1;
    }
    if (need) {
        if (!can_get(c)) return fail(c, "fmi2GetInteger: %s", "outputs need initialization mode");
        if (prepare_outputs(c) != fmi2OK) return fmi2Error;
    }
    for (k = 0; k < nvr; k++) value[k] = c->s.i[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    int need = 0;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_BOOLEAN)
            return fail(c, "fmi2GetBoolean: %s", "unknown value reference");
        if (HPFMU_BOOLEAN_KIND[vr[k]] == 'o') need = 1;
    }
    if (need) {
        if (!can_get(c)) return fail(c, "fmi2GetBoolean: %s", "outputs need initialization mode");
        if (prepare_outputs(c) != fmi2OK) return fmi2Error;
    }
    for (k = 0; k < nvr; k++) value[k] = c->s.b[vr[k]] ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_STRING) return fail(c, "fmi2GetString: %s", "unknown value reference");
        value[k] = HPFMU_STRING_START[vr[k]];
    }
    return fmi2OK;
}

/* may variable kind `kind` be set in the current mode? */
static fmi2Status check_set(Inst *c, char kind, const char *name) {
    int before_init = c->s.mode == MODE_INSTANTIATED || c->s.mode == MODE_INIT;
    if (kind == 'i' && (before_init || c->s.mode == MODE_STEP)) return fmi2OK;
    if (kind == 'p' && before_init) return fmi2OK;
    if (kind == 'p')
        return fail(c, "parameter %s can only be set before fmi2ExitInitializationMode", name);
    return fail(c, "variable %s cannot be set (output or constant)", name);
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_REAL) return fail(c, "fmi2SetReal: %s", "unknown value reference");
        if (check_set(c, HPFMU_REAL_KIND[vr[k]], HPFMU_REAL_NAME[vr[k]]) != fmi2OK)
            return fmi2Error;
    }
    for (k = 0; k < nvr; k++) {
        c->s.r[vr[k]] = value[k];
        if (vr[k] == VR_U_KNEE) c->s.up[0] = bounded_torque(&c->s, 0, value[k]);
        if (vr[k] == VR_U_ANKLE) c->s.up[1] = bounded_torque(&c->s, 1, value[k]);
    }
    c->s.outputs_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_INTEGER)
            return fail(c, "fmi2SetInteger: %s", "unknown value reference");
        if (check_set(c, HPFMU_INTEGER_KIND[vr[k]], HPFMU_INTEGER_NAME[vr[k]]) != fmi2OK)
            return fmi2Error;
    }
    for (k = 0; k < nvr; k++) c->s.i[vr[k]] = value[k];
    c->s.outputs_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_BOOLEAN)
            return fail(c, "fmi2SetBoolean: %s", "unknown value reference");
        if (check_set(c, HPFMU_BOOLEAN_KIND[vr[k]], HPFMU_BOOLEAN_NAME[vr[k]]) != fmi2OK)
            return fmi2Error;
    }
    for (k = 0; k < nvr; k++) c->s.b[vr[k]] = value[k] ? 1 : 0;
    c->s.outputs_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    Inst *c = (Inst *)comp;
    (void)value;
    if (c == NULL) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (vr[0] >= HPFMU_N_STRING) return fail(c, "fmi2SetString: %s", "unknown value reference");
    return fail(c, "variable %s cannot be set (constant)", HPFMU_STRING_NAME[vr[0]]);
}

/* -- FMU state ---------------------------------------------------------------------------------- */
fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    Inst *c = (Inst *)comp;
    Data *copy;
    if (c == NULL || state == NULL) return fmi2Error;
    copy = (Data *)(*state ? *state : xalloc(1, sizeof(Data)));
    if (copy == NULL) return fail(c, "fmi2GetFMUstate: %s", "out of memory");
    *copy = c->s;
    *state = copy;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate state) {
    Inst *c = (Inst *)comp;
    if (c == NULL || state == NULL) return fmi2Error;
    c->s = *(const Data *)state;
    c->s.outputs_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    (void)comp;
    if (state == NULL) return fmi2OK;
    free(*state);
    *state = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate state, size_t *size) {
    (void)state;
    (void)size;
    return fail((Inst *)comp, "%s is not supported", "FMU state serialization");
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate state, fmi2Byte bytes[],
                                 size_t size) {
    (void)state; (void)bytes; (void)size;
    return fail((Inst *)comp, "%s is not supported", "FMU state serialization");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state) {
    (void)bytes; (void)size; (void)state;
    return fail((Inst *)comp, "%s is not supported", "FMU state serialization");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vUnknown[],
                                        size_t nUnknown, const fmi2ValueReference vKnown[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown; (void)nUnknown; (void)vKnown; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    return fail((Inst *)comp, "%s is not supported", "fmi2GetDirectionalDerivative");
}

/* -- co-simulation ------------------------------------------------------------------------------ */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    return fail((Inst *)comp, "%s is not supported (inputs are held)", "input derivatives");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    return fail((Inst *)comp, "%s is not supported", "output derivatives");
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Inst *c = (Inst *)comp;
    Data *s;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (c == NULL) return fmi2Error;
    s = &c->s;
    if (s->mode != MODE_STEP) return fail(c, "fmi2DoStep: %s", "not in step mode");
    if (!(communicationStepSize >= 0) || !isfinite(currentCommunicationPoint))
        return fail(c, "fmi2DoStep: %s", "the step size must be >= 0 and the time finite");
    if (!isfinite(s->up[0]) || !isfinite(s->up[1]))
        return fail(c, "fmi2DoStep: %s", "the prosthesis torque inputs are not finite");
    if (s->failed) return fmi2Discard; /* the walk has ended: the state stays at the fall */
    if (communicationStepSize == 0) return fmi2OK;
    s->time = currentCommunicationPoint;
    {
        /* friction-cone check with the torques held over this step (the vector field is
           already evaluated if the outputs were read after the inputs were set) */
        double fz, fx;
        if (!s->outputs_valid) eval_field(c);
        fz = c->lam[1];
        fx = c->lam[0];
        s->bad_cone = (fz < s->min_normal_force || fabs(fx) > s->mu * fz) ? s->bad_cone + 1 : 0;
        if (s->bad_cone >= s->cone_periods) {
            set_fall(c, 5);  /* decided before integrating: the state of time t is held */
            return fmi2Discard;
        }
    }
    {
        /* the state at the start of the step, held if the step ends non-finite or blown up */
        double x0[NX], z0 = s->z_prev, peak0 = s->tau_peak, ti0 = s->t_impact, ts0 = s->t_step;
        int d0 = s->d, steps0 = s->steps;
        memcpy(x0, s->x, sizeof x0);
        s->heel = 0;
        integrate(c, currentCommunicationPoint, communicationStepSize);
        s->time = currentCommunicationPoint + communicationStepSize;
        state_checks(c);
        s->outputs_valid = 0;
        if (!s->failed) return fmi2OK;
        if (s->fall_code == 1 || s->fall_code == 8) {
            memcpy(s->x, x0, sizeof x0);
            s->d = d0;
            s->steps = steps0;
            s->z_prev = z0;
            s->tau_peak = peak0;
            s->t_impact = ti0;
            s->t_step = ts0;
            s->time = currentCommunicationPoint;
        }
        return fmi2Discard;
    }
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    return fail((Inst *)comp, "%s is not supported (doStep is synchronous)", "fmi2CancelStep");
}

fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value) {
    (void)s;
    (void)value;
    return fail((Inst *)comp, "%s is not supported", "fmi2GetStatus");
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {  /* after a fall: the time of the state held */
        *value = c->s.time;
        return fmi2OK;
    }
    return fail(c, "%s: only fmi2LastSuccessfulTime", "fmi2GetRealStatus");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s;
    (void)value;
    return fail((Inst *)comp, "%s is not supported", "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s,
                                fmi2Boolean *value) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    if (s == fmi2Terminated) {  /* a fall ends the walk */
        *value = c->s.failed ? fmi2True : fmi2False;
        return fmi2OK;
    }
    return fail(c, "%s: only fmi2Terminated", "fmi2GetBooleanStatus");
}

fmi2Status fmi2GetStringStatus(fmi2Component comp, const fmi2StatusKind s, fmi2String *value) {
    (void)s;
    (void)value;
    return fail((Inst *)comp, "%s is not supported", "fmi2GetStringStatus");
}
