/* Seesaw: the IP02 cart on SEESAW-E. Its equations are not written here: seesaw_casadi.c is generated from
 * the CasADi model (pendulab.model.seesaw) at build time. This file only steps them.
 *
 * The parameters are laid out in the real array in the order of SeesawParameters, so that the array slice
 * starting at VR_FIRST_PARAMETER is the CasADi parameter vector itself; likewise the states x..thetadot. */
#include <math.h>
#include <string.h>

#include "fmu_model.h"
#include "seesaw_casadi.h"

#define STATE(comp) (&(comp)->r[VR_x])
#define PARAMS(comp) (&(comp)->r[VR_FIRST_PARAMETER])

typedef struct {
    double next[N_SEESAW_STATES];
    double y[4];
    double w[SEESAW_WORK_DOUBLES];
    long long int iw[SEESAW_WORK_INTS];
} Work;

size_t model_work_size(void) { return sizeof(Work); }

void model_reset(Instance *comp) { (void)comp; }

/* Every parameter's range and the start inside the end stops are checked by fmu_common.c from the variable
 * table (config.py); the speeds have no range, so they are checked here. */
Status model_initialize(Instance *comp) {
    int k;
    for (k = 0; k < N_SEESAW_STATES; k++) {
        if (!isfinite(STATE(comp)[k])) {
            fmu_log(comp, Error, "logStatusError", "start state %s is not finite", k < 2 ? (k ? "xdot" : "x") : (k == 2 ? "theta" : "thetadot"));
            return Error;
        }
    }
    return OK;
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
        seesaw_rk4(arg, res, w->iw, w->w, 0);
        memcpy(STATE(comp), w->next, sizeof(w->next));
    }
    if (!isfinite(comp->r[VR_x]) || !isfinite(comp->r[VR_theta])) {
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
    seesaw_outputs(arg, res, w->iw, w->w, 0);
    comp->r[VR_theta_measured] = w->y[0];
    comp->r[VR_x_measured] = w->y[1];
    comp->r[VR_V_applied] = w->y[2];
    comp->r[VR_F_friction] = w->y[3];
}
