/* Plant: the cart-pendulum. Its equations are not written here: plant_casadi.c is generated from the
 * CasADi model (pendulab.model.plant) at build time. This file only steps them.
 *
 * The parameters are laid out in the real array in the order of PlantParameters, so that the array
 * slice starting at VR_FIRST_PARAMETER is the CasADi parameter vector itself; likewise the states. */
#include <math.h>
#include <string.h>

#include "fmu_model.h"
#include "plant_casadi.h"

Status model_event_update(Instance *comp, int *states_changed);

#define STATE(comp) (&(comp)->r[VR_x])
#define PARAMS(comp) (&(comp)->r[VR_FIRST_PARAMETER])

/* The generated functions need scratch vectors; their sizes are fixed by the generated code.
 * regime is Model Exchange's discrete state (pendulab.model.plant.REGIME: friction regime, current-limit
 * branch, end stop, encoder counts): it changes only in event mode, so the right-hand side
 * (plant_ode_regime) is smooth between events and the event indicators (plant_indicators) mark
 * every switch. Co-Simulation's RK4 decides the switches at each evaluation (plant_rk4). */
typedef struct {
    double regime[N_REGIME];
    double regime_next[N_REGIME];
    double next[N_STATES];
    double derivative[N_STATES];
    double y[4];
    double w[PLANT_WORK_DOUBLES];
    long long int iw[PLANT_WORK_INTS];
} Work;

size_t model_work_size(void) { return sizeof(Work); }

void model_reset(Instance *comp) { (void)comp; }

/* Every parameter's range and the conditions between them (lp <= Lp, the start inside the track, ...) are checked
 * by fmu_common.c from the variable table: here only the discrete state is set up. */
Status model_initialize(Instance *comp) {
    int changed;
    memset(((Work *)comp->work)->regime, 0, sizeof(((Work *)comp->work)->regime));
    return model_event_update(comp, &changed);
}

Status model_event_update(Instance *comp, int *states_changed) {
    Work *w = (Work *)comp->work;
    const double *arg[5];
    double *res[2];
    double t = comp->time;
    int round;
    *states_changed = 0;
    if (!isfinite(comp->r[VR_V])) {
        fmu_log(comp, Error, "logStatusError", "input V=%g is not finite at t=%g", comp->r[VR_V], t);
        return Error;
    }
    arg[0] = STATE(comp); arg[1] = &comp->r[VR_V]; arg[2] = PARAMS(comp); arg[3] = &t; arg[4] = w->regime;
    res[0] = w->regime_next; res[1] = w->next;
    /* Iterate to a fixed point: a stop reached resets the speed, which may change the friction regime. */
    for (round = 0; round < 8; round++) {
        plant_event(arg, res, w->iw, w->w, 0);
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
    arg[0] = STATE(comp); arg[1] = &comp->r[VR_V]; arg[2] = PARAMS(comp); arg[3] = &t; arg[4] = w->regime;
    res[0] = z;
    plant_indicators(arg, res, w->iw, w->w, 0);
}

static void ode(Instance *comp, const double *state, double t, double *derivative) {
    Work *w = (Work *)comp->work;
    const double *arg[5];
    double *res[1];
    arg[0] = state; arg[1] = &comp->r[VR_V]; arg[2] = PARAMS(comp); arg[3] = &t; arg[4] = w->regime;
    res[0] = derivative;
    /* Model Exchange: the switches as the last event left them; Co-Simulation: decided here. */
    if (comp->type == ModelExchange) plant_ode_regime(arg, res, w->iw, w->w, 0);
    else plant_ode(arg, res, w->iw, w->w, 0);
}

Status model_do_step(Instance *comp, double t, double h) {
    Work *w = (Work *)comp->work;
    const double *arg[5];
    double *res[1];
    double ts, hs;
    /* Equal RK4 sub-steps of at most MAX_SUBSTEP, the same rule as pendulab.model.plant.substeps. */
    int n = (int)ceil(h / MAX_SUBSTEP - 1e-9), k;
    if (n < 1) n = 1;
    /* fmin/fmax ignore NaN, so the saturation would turn a NaN command into -V_max: refuse it instead. */
    if (!isfinite(comp->r[VR_V])) {
        fmu_log(comp, Error, "logStatusError", "input V=%g is not finite at t=%g", comp->r[VR_V], t);
        return Error;
    }
    hs = h / n;
    arg[1] = &comp->r[VR_V]; arg[2] = PARAMS(comp); arg[3] = &ts; arg[4] = &hs;
    res[0] = w->next;
    for (k = 0; k < n; k++) {
        ts = t + k * hs;
        arg[0] = STATE(comp);
        plant_rk4(arg, res, w->iw, w->w, 0);
        memcpy(STATE(comp), w->next, sizeof(w->next));
    }
    if (!isfinite(comp->r[VR_x]) || !isfinite(comp->r[VR_alpha])) {
        fmu_log(comp, Error, "logStatusError", "the state became non-finite at t=%g (check V and the parameters)", t + h);
        return Error;
    }
    return OK;
}

void model_update_outputs(Instance *comp) {
    Work *w = (Work *)comp->work;
    const double *arg[4];
    double *res[1];
    double t = comp->time;
    arg[0] = STATE(comp); arg[1] = &comp->r[VR_V]; arg[2] = PARAMS(comp); arg[3] = &t;
    res[0] = w->y;
    plant_outputs(arg, res, w->iw, w->w, 0);
    comp->r[VR_alpha_measured] = w->y[0];
    comp->r[VR_x_measured] = w->y[1];
    comp->r[VR_V_applied] = w->y[2];
    comp->r[VR_F_friction] = w->y[3];
    ode(comp, STATE(comp), t, w->derivative);
    memcpy(&comp->r[VR_der_x], w->derivative, sizeof(w->derivative));
}

void model_get_states(Instance *comp, double x[]) { memcpy(x, STATE(comp), N_STATES * sizeof(double)); }

void model_set_states(Instance *comp, const double x[]) { memcpy(STATE(comp), x, N_STATES * sizeof(double)); }

void model_get_derivatives(Instance *comp, double dx[]) {
    ode(comp, STATE(comp), comp->time, dx);
}

double model_next_time_event(Instance *comp) {
    /* The poke switches on and off at known times: report them so an integrator does not step over them. */
    double on = comp->r[VR_poke_start], off = on + comp->r[VR_poke_duration];
    if (comp->r[VR_poke_magnitude] == 0 || comp->r[VR_poke_duration] <= 0) return -1;
    if (comp->time < on) return on;
    if (comp->time < off) return off;
    return -1;
}
