/* Supervisor: the lab control logic (SPEC §5). Co-Simulation only, no continuous states.
 *
 * One function, evaluate(), holds the whole state machine. It is run twice per communication step:
 *  - in model_update_outputs on a scratch copy of the committed memory, from the current inputs, so that
 *    the gated voltage is already 0 in the communication step in which the master sets an over-limit
 *    input (direct feedthrough: a trip cuts the voltage within one control period);
 *  - in model_do_step on the committed memory itself, with logging: this commits (latches) what the
 *    outputs already showed, stamped with the communication point at which it was seen.
 * Running the same code both times guarantees that the outputs and the latched state agree.
 *
 * The two optional modes live here too, so that they run identically in simulation and on the rig:
 *  - re-centring (the old lab's "kickback"): a slow outer loop on the measured cart position that acts
 *    through the controller's reference r (output r), engaged beyond recentre_x_on, released inside
 *    recentre_x_off, slew- and size-limited; the student's controller runs as entered;
 *  - swing-up (Quanser's self-erecting pendulum): the Astrom-Furuta energy law asks for a cart
 *    acceleration, a set point integrates it (speed <= swing_speed_max, travel <= swing_travel) and a cart
 *    servo follows the set point, clamped to swing_V_limit; inside the catch window the controller is
 *    engaged from reset (output controller_engaged), and a fall within catch_hold swings again.
 * Their speeds are filtered differences of the measurements, kept in the memory.
 *
 * The state, trip and command codes come from config.py through variables.h. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <string.h>

#include "fmu_model.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif
#define DEG(rad) ((rad) * 180.0 / M_PI)

typedef struct {
    int state;
    int trip_reason;
    double trip_time;
    int last_command;     /* command input value already handled: act on a change to a non-zero code */
    int last_iteration;   /* iteration input value already announced */
    /* speed estimates: filtered differences of the measurements at the previous evaluation */
    int have_previous;
    double t_previous, x_previous, alpha_previous, xdot, alphadot;
    /* re-centring */
    int recentring;
    double r;
    /* swing-up: the cart's set point, when the swing started, when the last catch happened */
    double x_set, v_set, swing_started, swing_entered, caught_at, swing_voltage;
    int misses;
} Memory;

size_t model_work_size(void) { return sizeof(Memory); }

#define MEMORY(comp) ((Memory *)(comp)->work)
#define RIG(comp) ((comp)->b[VR_rig_mode])
#define CALIBRATION(comp) ((comp)->b[VR_calibration_mode])
#define SWING_UP(comp) ((comp)->b[VR_swing_up] && !CALIBRATION(comp))
#define RECENTRE(comp) ((comp)->b[VR_recentre] && !CALIBRATION(comp))

static double clamp(double v, double limit) { return v > limit ? limit : v < -limit ? -limit : v; }

static double wrap(double a) {
    a = fmod(a, 2 * M_PI);  /* in (-2 pi, 2 pi) */
    if (a <= -M_PI) a += 2 * M_PI;
    else if (a > M_PI) a -= 2 * M_PI;
    return a;
}

static const char *state_name(int state) {
    return state >= 0 && state < N_STATE_CODES ? STATE_NAMES[state] : "?";
}

/* Angle in the upright convention, in (-pi, pi]. On the rig the encoder reads 0 hanging down; in a
 * simulated swing-up the pendulum may turn over, so the angle is wrapped too. */
static double upright_angle(const Instance *comp) {
    double a = comp->r[VR_alpha_measured];
    if (!isfinite(a)) return a;
    if (RIG(comp)) return wrap(a - M_PI);
    return SWING_UP(comp) ? wrap(a) : a;
}

/* Announce one line in the category logEvents, prefixed with the time. */
static void announce(Instance *comp, double t, const char *format, ...) {
    char text[512];
    va_list args;
    va_start(args, format);
    vsnprintf(text, sizeof(text), format, args);
    va_end(args);
    fmu_log(comp, OK, "logEvents", "t=%.3f s: %s", t, text);
}

/* Change state; with `log`, announce "from -> to (why)". */
static void go(Instance *comp, Memory *m, int to, double t, int log, const char *why) {
    if (log) announce(comp, t, "%s -> %s (%s)", state_name(m->state), state_name(to), why);
    if (to == STATE_SWINGING && m->state != STATE_SWINGING) m->swing_entered = t;
    m->state = to;
}

/* The state a start leads to: in rig mode the controller waits for the capture window (not in
 * calibration mode, where the pendulum is removed). */
static int started_state(const Instance *comp) {
    if (SWING_UP(comp)) return STATE_SWINGING;
    return RIG(comp) && !CALIBRATION(comp) ? STATE_WAITING : STATE_RUNNING;
}

/* Whether the trip condition has cleared, so that a trip may be re-armed; if not, why not. In rig mode
 * the angle is not required to be within alpha_max (the pendulum hangs after a trip): the capture
 * window guards the engagement instead. */
static int limits_ok(const Instance *comp, double alpha, char *why, size_t n) {
    double x = comp->r[VR_x_measured], v = comp->r[VR_V_command];
    int check_angle = !CALIBRATION(comp) && !RIG(comp) && !SWING_UP(comp);
    if (!isfinite(x) || (!CALIBRATION(comp) && !isfinite(alpha))) {
        snprintf(why, n, "the measurements are not finite");
        return 0;
    }
    if (check_angle && fabs(alpha) > comp->r[VR_alpha_max]) {
        snprintf(why, n, "|alpha| = %.1f deg > %.1f deg", DEG(fabs(alpha)), DEG(comp->r[VR_alpha_max]));
        return 0;
    }
    if (fabs(x) > comp->r[VR_x_max]) {
        snprintf(why, n, "|x| = %.3f m > %.3f m", fabs(x), comp->r[VR_x_max]);
        return 0;
    }
    if (!isfinite(v)) {
        snprintf(why, n, "V_command = %g is not finite", v);
        return 0;
    }
    return 1;
}

/* Calibration mode: a start needs the cart centred. The seesaw (level_start): a start needs it level. */
static int start_rule(const Instance *comp, double alpha, char *why, size_t n) {
    double x = comp->r[VR_x_measured];
    if (comp->b[VR_level_start] && !(fabs(alpha) < comp->r[VR_capture_window])) {
        snprintf(why, n, "the seesaw is not level: |tilt| = %.1f deg, must be < %.1f deg (capture_window); hold it level, then start",
                 DEG(fabs(alpha)), DEG(comp->r[VR_capture_window]));
        return 0;
    }
    if (!CALIBRATION(comp) || fabs(x) < comp->r[VR_centre_tolerance]) return 1;
    snprintf(why, n, "calibration mode needs the cart centred: |x| = %.4f m, must be < %.4f m; centre the cart first",
             fabs(x), comp->r[VR_centre_tolerance]);
    return 0;
}

static void clear_trip(Memory *m) {
    m->trip_reason = TRIP_NONE;
    m->trip_time = -1;
}

/* A new swing-up attempt: its time limit counts from here, its misses from 0. */
static void start_swing_clock(Memory *m, double t) {
    m->swing_started = t;
    m->misses = 0;
    m->caught_at = -1;
}

static void handle_command(Instance *comp, Memory *m, int command, double alpha, double t, int log) {
    char why[256];
    switch (command) {
    case CMD_START:
        if (m->state == STATE_IDLE || m->state == STATE_PAUSED) {
            if (!start_rule(comp, alpha, why, sizeof(why))) {
                if (log) announce(comp, t, "start refused: %s", why);
            } else {
                if (m->state == STATE_IDLE) start_swing_clock(m, t);
                go(comp, m, started_state(comp), t, log, m->state == STATE_IDLE ? "start" : "resume");
            }
        } else if (m->state == STATE_TRIPPED) {
            /* Start after a trip re-arms and starts in one go, under the same condition as re-arm. */
            if (!limits_ok(comp, alpha, why, sizeof(why)) || !start_rule(comp, alpha, why, sizeof(why))) {
                if (log) announce(comp, t, "start refused, still tripped (%s): %s", TRIP_NAMES[m->trip_reason], why);
            } else {
                clear_trip(m);
                start_swing_clock(m, t);
                go(comp, m, started_state(comp), t, log, "re-armed by start");
            }
        } else if (log) {
            announce(comp, t, "start ignored in state %s", state_name(m->state));
        }
        break;
    case CMD_PAUSE:
        if (m->state == STATE_RUNNING || m->state == STATE_WAITING || m->state == STATE_SWINGING) go(comp, m, STATE_PAUSED, t, log, "pause");
        else if (log) announce(comp, t, "pause ignored in state %s", state_name(m->state));
        break;
    case CMD_END:
        /* The trip reason and time (if any) stay as the record of the session. */
        if (m->state != STATE_ENDED) go(comp, m, STATE_ENDED, t, log, "end");
        else if (log) announce(comp, t, "end ignored: the session has already ended");
        break;
    case CMD_REARM:
        if (m->state != STATE_TRIPPED) {
            if (log) announce(comp, t, "re-arm ignored in state %s", state_name(m->state));
        } else if (!limits_ok(comp, alpha, why, sizeof(why))) {
            if (log) announce(comp, t, "re-arm refused, still tripped (%s): %s", TRIP_NAMES[m->trip_reason], why);
        } else {
            clear_trip(m);
            go(comp, m, STATE_IDLE, t, log, "re-armed");
        }
        break;
    default:
        if (log) announce(comp, t, "unknown command %d ignored (0 none, 1 start, 2 pause, 3 end, 4 re-arm)", command);
    }
}

static void trip(Instance *comp, Memory *m, int reason, double t, int log, const char *detail) {
    char why[320];
    if (log) {
        snprintf(why, sizeof(why), "%s %s", TRIP_NAMES[reason], detail);
        go(comp, m, STATE_TRIPPED, t, log, why);
    }
    m->state = STATE_TRIPPED;
    m->trip_reason = reason;
    m->trip_time = t;
}

/* While swinging up: the limits of the swing (time, travel, finite measurements), then the catch window. */
static void swing_checks(Instance *comp, Memory *m, double alpha, double t, int log) {
    char detail[256];
    double x = comp->r[VR_x_measured];
    detail[0] = '\0';
    if (!isfinite(x) || !isfinite(alpha)) {
        if (log) snprintf(detail, sizeof(detail), "while swinging up (alpha = %g rad, x = %g m)", alpha, x);
        trip(comp, m, TRIP_MEASUREMENT, t, log, detail);
    } else if (fabs(x) > fmin(comp->r[VR_swing_x_limit], comp->r[VR_x_max])) {
        if (log) snprintf(detail, sizeof(detail), "while swinging up: |x| = %.3f m > %.3f m", fabs(x), fmin(comp->r[VR_swing_x_limit], comp->r[VR_x_max]));
        trip(comp, m, TRIP_TRACK, t, log, detail);
    } else if (t - m->swing_started > comp->r[VR_swing_time_max]) {
        if (log) snprintf(detail, sizeof(detail), "not caught within swing_time_max = %.1f s (%d missed)", comp->r[VR_swing_time_max], m->misses);
        trip(comp, m, TRIP_SWING_TIME, t, log, detail);
    } else if (t - m->swing_entered >= 5 * comp->r[VR_rate_filter] && m->have_previous  /* the speed estimate has settled */
               && fabs(x) < comp->r[VR_catch_x] && fabs(alpha) < comp->r[VR_catch_alpha] && fabs(m->alphadot) < comp->r[VR_catch_rate]) {
        if (log) snprintf(detail, sizeof(detail), "caught: |alpha| = %.1f deg, |dalpha/dt| = %.0f deg/s, x = %+.3f m; controller engaged",
                          DEG(fabs(alpha)), DEG(fabs(m->alphadot)), x);
        m->caught_at = t;
        go(comp, m, STATE_RUNNING, t, log, detail);
    }
}

/* Capture (rig mode), the catch (swing-up) and the trip checks while running. */
static void supervise(Instance *comp, Memory *m, double alpha, double t, int log) {
    char detail[256];
    double x = comp->r[VR_x_measured], v = comp->r[VR_V_command];
    double alpha_max = comp->r[VR_alpha_max], x_max = comp->r[VR_x_max];
    int calibration = CALIBRATION(comp);

    if (m->state == STATE_WAITING && fabs(alpha) < comp->r[VR_capture_window] && fabs(x) <= x_max) {
        snprintf(detail, sizeof(detail), "captured: |alpha| = %.1f deg < %.1f deg", DEG(fabs(alpha)),
                 DEG(comp->r[VR_capture_window]));
        go(comp, m, STATE_RUNNING, t, log, detail);
    }
    if (m->state == STATE_SWINGING) {
        swing_checks(comp, m, alpha, t, log);
        return;
    }
    if (m->state != STATE_RUNNING) return;
    if (SWING_UP(comp) && m->caught_at >= 0 && t - m->caught_at < comp->r[VR_catch_hold] && isfinite(alpha)
        && fabs(alpha) > alpha_max) {
        m->misses++;
        if (m->misses >= comp->i[VR_swing_tries]) {
            if (log) snprintf(detail, sizeof(detail), "%d of %d tries: |alpha| = %.1f deg > %.1f deg %.2f s after the catch",
                              m->misses, comp->i[VR_swing_tries], DEG(fabs(alpha)), DEG(alpha_max), t - m->caught_at);
            trip(comp, m, TRIP_CATCH, t, log, detail);
        } else {
            snprintf(detail, sizeof(detail), "catch missed (%d of %d tries): |alpha| = %.1f deg > %.1f deg %.2f s after the catch; swinging again",
                     m->misses, comp->i[VR_swing_tries], DEG(fabs(alpha)), DEG(alpha_max), t - m->caught_at);
            go(comp, m, STATE_SWINGING, t, log, detail);
        }
        return;
    }
    detail[0] = '\0';
    if (!isfinite(x) || (!calibration && !isfinite(alpha))) {
        if (log) snprintf(detail, sizeof(detail), "(alpha = %g rad, x = %g m)", alpha, x);
        trip(comp, m, TRIP_MEASUREMENT, t, log, detail);
    } else if (!calibration && fabs(alpha) > alpha_max) {
        if (log) snprintf(detail, sizeof(detail), "|alpha| = %.1f deg > %.1f deg", DEG(fabs(alpha)), DEG(alpha_max));
        trip(comp, m, TRIP_ANGLE, t, log, detail);
    } else if (fabs(x) > x_max) {
        if (log) snprintf(detail, sizeof(detail), "|x| = %.3f m > %.3f m", fabs(x), x_max);
        trip(comp, m, TRIP_TRACK, t, log, detail);
    } else if (!isfinite(v)) {
        if (log) snprintf(detail, sizeof(detail), "V_command = %g", v);
        trip(comp, m, TRIP_VOLTAGE, t, log, detail);
    }
}

/* Speeds from the measurements: differences since the previous evaluation, low-pass filtered. */
static void estimate(const Instance *comp, Memory *m, double alpha, double t) {
    double x = comp->r[VR_x_measured], dt = t - m->t_previous;
    if (!isfinite(x) || !isfinite(alpha)) {
        m->have_previous = 0;
        return;
    }
    if (m->have_previous && dt > 0) {
        double k = dt / (comp->r[VR_rate_filter] + dt);
        m->xdot += k * ((x - m->x_previous) / dt - m->xdot);
        m->alphadot += k * (wrap(alpha - m->alpha_previous) / dt - m->alphadot);
    } else if (!m->have_previous) {
        m->xdot = m->alphadot = 0;
    }
    m->have_previous = 1;
    m->t_previous = t;
    m->x_previous = x;
    m->alpha_previous = alpha;
}

/* Normalized energy of the pendulum: 0 at rest upright, -2 at rest hanging. */
static double energy(const Instance *comp, const Memory *m, double alpha) {
    double w0 = comp->r[VR_pendulum_frequency];
    return 0.5 * m->alphadot * m->alphadot / (w0 * w0) + cos(alpha) - 1.0;
}

/* The swing-up (Astrom-Furuta energy law on the cart's acceleration, through a set point that a cart servo
 * follows). dt: time since the previous evaluation. */
static void swing(Instance *comp, Memory *m, double alpha, double dt) {
    double x = comp->r[VR_x_measured], wc = comp->r[VR_swing_centring];
    double s = m->alphadot * cos(alpha);
    double direction = s < 0 ? -1.0 : 1.0;  /* at rest: push to +x to start the swing */
    double a = clamp(comp->r[VR_swing_energy_gain] * (comp->r[VR_swing_energy_target] - energy(comp, m, alpha)) * direction,
                     comp->r[VR_swing_accel_max]);
    double v;
    a -= wc * wc * m->x_set + 2.0 * wc * m->v_set;
    v = comp->r[VR_swing_kp] * (m->x_set - x) + comp->r[VR_swing_kd] * (m->v_set - m->xdot) + comp->r[VR_swing_kff] * m->v_set;
    m->swing_voltage = isfinite(v) ? clamp(v, comp->r[VR_swing_V_limit]) : 0.0;
    if (dt > 0) {
        m->v_set = clamp(m->v_set + a * dt, comp->r[VR_swing_speed_max]);
        m->x_set += m->v_set * dt;
        if (fabs(m->x_set) > comp->r[VR_swing_travel]) {
            m->x_set = clamp(m->x_set, comp->r[VR_swing_travel]);
            m->v_set = 0;
        }
    }
}

/* Re-centring: r follows the cart (r = gain * x) while engaged, else returns to 0, never faster than the slew.
 * x is the cart's position predicted recentre_lead ahead from its speed (0: the measured position). */
static void recentre(Instance *comp, Memory *m, double t, double dt, int log) {
    double x = comp->r[VR_x_measured] + comp->r[VR_recentre_lead] * m->xdot, target = 0.0, step;
    if (!isfinite(x)) return;
    if (!m->recentring && fabs(x) > comp->r[VR_recentre_x_on]) {
        m->recentring = 1;
        if (log) announce(comp, t, "re-centring engaged: |x| = %.3f m > %.3f m", fabs(x), comp->r[VR_recentre_x_on]);
    } else if (m->recentring && fabs(x) < comp->r[VR_recentre_x_off]) {
        m->recentring = 0;
        if (log) announce(comp, t, "re-centring released: |x| = %.3f m < %.3f m", fabs(x), comp->r[VR_recentre_x_off]);
    }
    if (m->recentring) target = clamp(comp->r[VR_recentre_gain] * x, comp->r[VR_recentre_r_max]);
    step = comp->r[VR_recentre_slew] * (dt > 0 ? dt : 0.0);
    m->r += clamp(target - m->r, step);
}

/* The whole state machine for the inputs now present, at communication point t. */
static void evaluate(Instance *comp, Memory *m, double t, int log) {
    double alpha = upright_angle(comp), dt = m->have_previous ? t - m->t_previous : 0.0;
    estimate(comp, m, alpha, t);
    int command = comp->i[VR_command], iteration = comp->i[VR_iteration];
    if (iteration != m->last_iteration) {
        if (log) announce(comp, t, "calibration iteration %d", iteration);
        m->last_iteration = iteration;
    }
    if (command != m->last_command) {
        if (command != CMD_NONE) handle_command(comp, m, command, alpha, t, log);
        m->last_command = command;
    }
    supervise(comp, m, alpha, t, log);
    if (m->state == STATE_SWINGING) {
        swing(comp, m, alpha, dt);
    } else {
        /* The set point waits on the cart, so that a swing starts where the cart is. */
        m->x_set = isfinite(comp->r[VR_x_measured]) ? comp->r[VR_x_measured] : 0.0;
        m->v_set = 0;
        m->swing_voltage = 0;
    }
    if (m->state == STATE_RUNNING && RECENTRE(comp)) {
        recentre(comp, m, t, dt, log);
    } else {
        if (m->recentring && log) announce(comp, t, "re-centring released (%s)", state_name(m->state));
        m->recentring = 0;
        m->r = 0.0;  /* the controller restarts from reset with r = 0 when it engages again */
    }
}

/* ------------------------------------------------------------------ the model contract */
void model_reset(Instance *comp) {
    Memory *m = MEMORY(comp);
    m->state = STATE_IDLE;
    clear_trip(m);
    m->last_command = CMD_NONE;
    m->last_iteration = comp->i[VR_iteration];
    m->have_previous = 0;
    m->xdot = m->alphadot = 0;
    m->recentring = 0;
    m->r = 0;
    m->x_set = m->v_set = m->swing_voltage = 0;
    m->swing_started = 0;
    m->caught_at = -1;
    m->misses = 0;
}

/* The parameters' ranges (alpha_max 10 to 15 deg, the swing-up's and re-centring's, ...) and the conditions
 * between them (capture_window <= alpha_max, recentre_x_off < recentre_x_on < x_max, ...) are checked by
 * fmu_common.c from the variable table (config.py). */
Status model_initialize(Instance *comp) {
    Memory *m = MEMORY(comp);
    if (comp->b[VR_auto_start]) {
        handle_command(comp, m, CMD_START, upright_angle(comp), comp->time, 1);
        supervise(comp, m, upright_angle(comp), comp->time, 1);
    }
    return OK;
}

Status model_do_step(Instance *comp, double t, double h) {
    (void)h;
    evaluate(comp, MEMORY(comp), t, 1);
    return OK;
}

void model_update_outputs(Instance *comp) {
    Memory m = *MEMORY(comp);
    double v = comp->r[VR_V_command], limit = comp->r[VR_V_limit];
    if (comp->mode == MODE_STEP) evaluate(comp, &m, comp->time, 0);
    comp->r[VR_alpha] = upright_angle(comp);
    comp->r[VR_V] = m.state == STATE_RUNNING ? clamp(v, limit) : m.state == STATE_SWINGING ? clamp(m.swing_voltage, limit) : 0.0;
    comp->b[VR_motor_enable] = m.state == STATE_RUNNING || m.state == STATE_SWINGING;
    /* The reference is sampled: the value the last step committed, held until the next (no direct feedthrough,
     * so that controller -> supervisor -> controller through r is no algebraic loop; pendulab's master gave
     * the controller the previous point's r for its output already). */
    comp->r[VR_r] = MEMORY(comp)->r;
    comp->r[VR_swing_voltage] = m.swing_voltage;
    comp->r[VR_energy] = energy(comp, &m, comp->r[VR_alpha]);
    comp->b[VR_recentring] = m.recentring;
    comp->b[VR_controller_engaged] = !(SWING_UP(comp) && m.state != STATE_RUNNING);
    comp->i[VR_misses] = m.misses;
    comp->i[VR_state] = m.state;
    comp->i[VR_trip_reason] = m.trip_reason;
    comp->r[VR_trip_time] = m.trip_time;
}
