/* A CasADi state-space model behind fmu_model.h: the plant (cart-pendulum) and the seesaw are both this file.
 * Their equations are not written here: <prefix>_casadi.c is generated from the CasADi model
 * (pendulab.model.plant, pendulab.model.seesaw) at build time; this file only steps them
 * (pendulab.fmu.state_space writes the defines below into variables.h).
 *
 * The contract with the variable table: the states are consecutive from VR_FIRST_STATE, their derivatives from
 * VR_FIRST_DERIVATIVE, the outputs of <prefix>_outputs from VR_FIRST_OUTPUT, and the parameters from
 * VR_FIRST_PARAMETER in the CasADi parameter vector's order (so each array slice is the CasADi argument
 * itself); the input is V. The generated functions (CASADI(name) = <prefix>_name):
 *   ode(state, V, p, t) -> derivative            Co-Simulation's law: the switches decided at every evaluation
 *   rk4(state, V, p, t, h) -> state              one RK4 sub-step (with the end stops' projection)
 *   outputs(state, V, p, t) -> y[N_OUTPUTS]
 *   ode_regime(state, V, p, t, regime) -> derivative   Model Exchange: the switches frozen in regime
 *   indicators(state, V, p, t, regime) -> z       the event indicators (each switch's zero crossing)
 *   event(state, V, p, t, regime) -> (regime, state)   the event update: the regime the law picks here
 * regime is Model Exchange's discrete state (friction regime, current-limit branch, end stops, ...): it changes
 * only in event mode, so the right-hand side is smooth between events and the event indicators mark every switch.
 * A rectangular pulse (the plant's poke, the seesaw's tap) switches at known times: its edges are time events. */
#include <math.h>
#include <string.h>

#include "fmu_model.h"
#include CASADI_HEADER

#define PASTE_(a, b) a##_##b
#define PASTE(a, b) PASTE_(a, b)
#define CASADI(name) PASTE(CASADI_PREFIX, name)

Status model_event_update(Instance *comp, int *states_changed);

#define STATE(comp) (&(comp)->r[VR_FIRST_STATE])
#define PARAMS(comp) (&(comp)->r[VR_FIRST_PARAMETER])

/* Scratch vectors of the generated functions (their sizes fixed by the generated code) and the discrete state. */
typedef struct {
    double regime[N_REGIME];
    double regime_next[N_REGIME];
    double next[N_STATES];
    double derivative[N_STATES];
    double y[N_OUTPUTS];
    double w[CASADI_WORK_DOUBLES];
    long long int iw[CASADI_WORK_INTS];
} Work;

size_t model_work_size(void) { return sizeof(Work); }

void model_reset(Instance *comp) { (void)comp; }

/* fmin/fmax ignore NaN, so the saturation would turn a NaN command into -V_max: refuse it instead. */
static Status check_input(Instance *comp, double t) {
    if (isfinite(comp->r[VR_V])) return OK;
    fmu_log(comp, Error, "logStatusError", "input V=%g is not finite at t=%g", comp->r[VR_V], t);
    return Error;
}

/* Every parameter's range and the conditions between them (the start inside the end stops, ...) are checked by
 * fmu_common.c from the variable table; the speeds have no range, so the states' finiteness is checked here,
 * then the discrete state is set up. */
Status model_initialize(Instance *comp) {
    int changed, k;
    for (k = 0; k < N_STATES; k++) {
        if (!isfinite(STATE(comp)[k])) {
            fmu_log(comp, Error, "logStatusError", "start state %s is not finite", REAL_INFO[VR_FIRST_STATE + k].name);
            return Error;
        }
    }
    memset(((Work *)comp->work)->regime, 0, sizeof(((Work *)comp->work)->regime));
    return model_event_update(comp, &changed);
}

static void arguments(Instance *comp, const double **arg, const double *state, const double *t) {
    arg[0] = state; arg[1] = &comp->r[VR_V]; arg[2] = PARAMS(comp); arg[3] = t; arg[4] = ((Work *)comp->work)->regime;
}

Status model_event_update(Instance *comp, int *states_changed) {
    Work *w = (Work *)comp->work;
    const double *arg[5];
    double *res[2];
    double t = comp->time;
    int round;
    *states_changed = 0;
    if (check_input(comp, t) != OK) return Error;
    arguments(comp, arg, STATE(comp), &t);
    res[0] = w->regime_next; res[1] = w->next;
    /* Iterate to a fixed point: a stop reached resets a speed, which may change the friction regime. */
    for (round = 0; round < 8; round++) {
        CASADI(event)(arg, res, w->iw, w->w, 0);
        if (memcmp(w->next, STATE(comp), sizeof(w->next)) != 0) {
            memcpy(STATE(comp), w->next, sizeof(w->next));
            *states_changed = 1;
        } else if (memcmp(w->regime_next, w->regime, sizeof(w->regime)) == 0) {
            break;
        }
        memcpy(w->regime, w->regime_next, sizeof(w->regime));
    }
    comp->outputs_stale = 1;
    return OK;
}

void model_get_event_indicators(Instance *comp, double z[]) {
    Work *w = (Work *)comp->work;
    const double *arg[5];
    double *res[1];
    double t = comp->time;
    arguments(comp, arg, STATE(comp), &t);
    res[0] = z;
    CASADI(indicators)(arg, res, w->iw, w->w, 0);
}

static void ode(Instance *comp, const double *state, double t, double *derivative) {
    Work *w = (Work *)comp->work;
    const double *arg[5];
    double *res[1];
    arguments(comp, arg, state, &t);
    res[0] = derivative;
    /* Model Exchange: the switches as the last event left them; Co-Simulation: decided here. */
    if (comp->type == ModelExchange) CASADI(ode_regime)(arg, res, w->iw, w->w, 0);
    else CASADI(ode)(arg, res, w->iw, w->w, 0);
}

Status model_do_step(Instance *comp, double t, double h) {
    Work *w = (Work *)comp->work;
    const double *arg[5];
    double *res[1];
    double ts, hs;
    /* Equal RK4 sub-steps of at most MAX_SUBSTEP, the same rule as pendulab.model.plant.substeps. */
    int n = (int)ceil(h / MAX_SUBSTEP - 1e-9), k;
    if (n < 1) n = 1;
    if (check_input(comp, t) != OK) return Error;
    hs = h / n;
    arg[1] = &comp->r[VR_V]; arg[2] = PARAMS(comp); arg[3] = &ts; arg[4] = &hs;
    res[0] = w->next;
    for (k = 0; k < n; k++) {
        ts = t + k * hs;
        arg[0] = STATE(comp);
        CASADI(rk4)(arg, res, w->iw, w->w, 0);
        memcpy(STATE(comp), w->next, sizeof(w->next));
    }
    for (k = 0; k < N_STATES; k++) {
        if (!isfinite(STATE(comp)[k])) {
            fmu_log(comp, Error, "logStatusError", "the state became non-finite at t=%g (check V and the parameters)", t + h);
            return Error;
        }
    }
    return OK;
}

void model_update_outputs(Instance *comp) {
    Work *w = (Work *)comp->work;
    const double *arg[5];
    double *res[1];
    double t = comp->time;
    arguments(comp, arg, STATE(comp), &t);
    res[0] = w->y;
    CASADI(outputs)(arg, res, w->iw, w->w, 0);
    memcpy(&comp->r[VR_FIRST_OUTPUT], w->y, sizeof(w->y));
    ode(comp, STATE(comp), t, w->derivative);
    memcpy(&comp->r[VR_FIRST_DERIVATIVE], w->derivative, sizeof(w->derivative));
}

void model_get_states(Instance *comp, double x[]) { memcpy(x, STATE(comp), N_STATES * sizeof(double)); }

void model_set_states(Instance *comp, const double x[]) { memcpy(STATE(comp), x, N_STATES * sizeof(double)); }

void model_get_derivatives(Instance *comp, double dx[]) { ode(comp, STATE(comp), comp->time, dx); }

double model_next_time_event(Instance *comp) {
    /* The pulse switches on and off at known times: report them so an integrator does not step over them. */
    double on = comp->r[VR_PULSE_START], off = on + comp->r[VR_PULSE_DURATION];
    if (comp->r[VR_PULSE_MAGNITUDE] == 0 || comp->r[VR_PULSE_DURATION] <= 0) return -1;
    if (comp->time < on) return on;
    if (comp->time < off) return off;
    return -1;
}
