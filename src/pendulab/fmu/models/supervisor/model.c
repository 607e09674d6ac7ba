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
} Memory;

size_t model_work_size(void) { return sizeof(Memory); }

#define MEMORY(comp) ((Memory *)(comp)->work)
#define RIG(comp) ((comp)->b[VR_rig_mode])
#define CALIBRATION(comp) ((comp)->b[VR_calibration_mode])

static const char *state_name(int state) {
    return state >= 0 && state < N_STATE_CODES ? STATE_NAMES[state] : "?";
}

/* Angle in the upright convention, in (-pi, pi]. On the rig the encoder reads 0 hanging down. */
static double upright_angle(const Instance *comp) {
    double a = comp->r[VR_alpha_measured];
    if (!RIG(comp) || !isfinite(a)) return a;
    a = fmod(a - M_PI, 2 * M_PI);  /* in (-2 pi, 2 pi) */
    if (a <= -M_PI) a += 2 * M_PI;
    else if (a > M_PI) a -= 2 * M_PI;
    return a;
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
    m->state = to;
}

/* The state a start leads to: in rig mode the controller waits for the capture window (not in
 * calibration mode, where the pendulum is removed). */
static int started_state(const Instance *comp) {
    return RIG(comp) && !CALIBRATION(comp) ? STATE_WAITING : STATE_RUNNING;
}

/* Whether the trip condition has cleared, so that a trip may be re-armed; if not, why not. In rig mode
 * the angle is not required to be within alpha_max (the pendulum hangs after a trip): the capture
 * window guards the engagement instead. */
static int limits_ok(const Instance *comp, double alpha, char *why, size_t n) {
    double x = comp->r[VR_x_measured], v = comp->r[VR_V_command];
    int check_angle = !CALIBRATION(comp) && !RIG(comp);
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

/* Calibration mode: a start needs the cart centred. */
static int centred(const Instance *comp, char *why, size_t n) {
    double x = comp->r[VR_x_measured];
    if (!CALIBRATION(comp) || fabs(x) < comp->r[VR_centre_tolerance]) return 1;
    snprintf(why, n, "calibration mode needs the cart centred: |x| = %.4f m, must be < %.4f m; centre the cart first",
             fabs(x), comp->r[VR_centre_tolerance]);
    return 0;
}

static void clear_trip(Memory *m) {
    m->trip_reason = TRIP_NONE;
    m->trip_time = -1;
}

static void handle_command(Instance *comp, Memory *m, int command, double alpha, double t, int log) {
    char why[256];
    switch (command) {
    case CMD_START:
        if (m->state == STATE_IDLE || m->state == STATE_PAUSED) {
            if (!centred(comp, why, sizeof(why))) {
                if (log) announce(comp, t, "start refused: %s", why);
            } else {
                go(comp, m, started_state(comp), t, log, m->state == STATE_IDLE ? "start" : "resume");
            }
        } else if (m->state == STATE_TRIPPED) {
            /* Start after a trip re-arms and starts in one go, under the same condition as re-arm. */
            if (!limits_ok(comp, alpha, why, sizeof(why)) || !centred(comp, why, sizeof(why))) {
                if (log) announce(comp, t, "start refused, still tripped (%s): %s", TRIP_NAMES[m->trip_reason], why);
            } else {
                clear_trip(m);
                go(comp, m, started_state(comp), t, log, "re-armed by start");
            }
        } else if (log) {
            announce(comp, t, "start ignored in state %s", state_name(m->state));
        }
        break;
    case CMD_PAUSE:
        if (m->state == STATE_RUNNING || m->state == STATE_WAITING) go(comp, m, STATE_PAUSED, t, log, "pause");
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

/* Capture (rig mode) and the trip checks while running. */
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
    if (m->state != STATE_RUNNING) return;
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

/* The whole state machine for the inputs now present, at communication point t. */
static void evaluate(Instance *comp, Memory *m, double t, int log) {
    double alpha = upright_angle(comp);
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
}

/* ------------------------------------------------------------------ the model contract */
void model_reset(Instance *comp) {
    Memory *m = MEMORY(comp);
    m->state = STATE_IDLE;
    clear_trip(m);
    m->last_command = CMD_NONE;
    m->last_iteration = comp->i[VR_iteration];
}

Status model_initialize(Instance *comp) {
    const double deg = M_PI / 180.0;
    double alpha_max = comp->r[VR_alpha_max];
    Memory *m = MEMORY(comp);
    if (!(alpha_max >= ALPHA_MAX_MIN_DEG * deg - ALPHA_MAX_SLACK && alpha_max <= ALPHA_MAX_MAX_DEG * deg + ALPHA_MAX_SLACK)) {
        fmu_log(comp, Error, "logStatusError",
                "alpha_max = %g rad (%g deg) is outside the allowed %g to %g deg; set alpha_max between %.4f and %.4f rad",
                alpha_max, DEG(alpha_max), ALPHA_MAX_MIN_DEG, ALPHA_MAX_MAX_DEG, ALPHA_MAX_MIN_DEG * deg, ALPHA_MAX_MAX_DEG * deg);
        return Error;
    }
    if (!(comp->r[VR_x_max] > 0 && isfinite(comp->r[VR_x_max]))) {
        fmu_log(comp, Error, "logStatusError", "x_max = %g m must be positive and finite", comp->r[VR_x_max]);
        return Error;
    }
    if (!(comp->r[VR_capture_window] > 0 && comp->r[VR_capture_window] <= alpha_max)) {
        fmu_log(comp, Error, "logStatusError", "capture_window = %g rad must be > 0 and <= alpha_max = %g rad",
                comp->r[VR_capture_window], alpha_max);
        return Error;
    }
    if (!(comp->r[VR_centre_tolerance] > 0 && comp->r[VR_centre_tolerance] < comp->r[VR_x_max])) {
        fmu_log(comp, Error, "logStatusError", "centre_tolerance = %g m must be > 0 and < x_max = %g m",
                comp->r[VR_centre_tolerance], comp->r[VR_x_max]);
        return Error;
    }
    if (!(comp->r[VR_V_limit] > 0 && isfinite(comp->r[VR_V_limit]))) {
        fmu_log(comp, Error, "logStatusError", "V_limit = %g V must be positive and finite", comp->r[VR_V_limit]);
        return Error;
    }
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
    comp->r[VR_V] = m.state == STATE_RUNNING ? (v > limit ? limit : v < -limit ? -limit : v) : 0.0;
    comp->b[VR_motor_enable] = m.state == STATE_RUNNING;
    comp->i[VR_state] = m.state;
    comp->i[VR_trip_reason] = m.trip_reason;
    comp->r[VR_trip_time] = m.trip_time;
}
