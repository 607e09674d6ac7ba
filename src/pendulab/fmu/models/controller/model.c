/* Controller: discrete LTI block. x+ = A x + B e, V_command = C x + D e, with e = r - Lp*alpha_measured.
 * A (row-major, MAX_ORDER x MAX_ORDER), B and C are parameters laid out contiguously by value reference. */
#include <math.h>
#include <string.h>

#include "fmu_model.h"

#ifndef M_PI
#define M_PI 3.14159265358979323846
#endif

typedef struct {
    double x[MAX_ORDER];
    double next[MAX_ORDER];
} Work;

size_t model_work_size(void) { return sizeof(Work); }

void model_reset(Instance *comp) { (void)comp; /* fmu_common.c zeroes the work memory */ }

/* Every parameter's range (n, h, Lp, integral_index, integral_limit; the matrices' entries finite) is checked by
 * fmu_common.c when it is set, integral_index <= n on leaving initialization (config.py's CONSTRAINTS). */
Status model_initialize(Instance *comp) {
    memset(((Work *)comp->work)->x, 0, sizeof(((Work *)comp->work)->x));
    return OK;
}

static double error_signal(const Instance *comp) {
    double alpha = comp->r[VR_alpha_measured];
    if (comp->b[VR_wrap_angle] && isfinite(alpha) && (alpha > M_PI || alpha <= -M_PI)) {
        alpha = fmod(alpha, 2 * M_PI);
        if (alpha <= -M_PI) alpha += 2 * M_PI;
        else if (alpha > M_PI) alpha -= 2 * M_PI;
    }
    return comp->r[VR_r] - comp->r[VR_Lp] * alpha;
}

void model_update_outputs(Instance *comp) {
    const Work *w = (const Work *)comp->work;
    const double *C = &comp->r[VR_C_1];
    double e = error_signal(comp), y = comp->r[VR_D] * e;
    int k, n = comp->i[VR_n];
    y += comp->r[VR_D_x] * comp->r[VR_x_measured];  /* 0 for a SISO G(s): adding +0.0 changes no value */
    for (k = 0; k < n; k++) y += C[k] * w->x[k];
    comp->r[VR_e] = e;
    comp->r[VR_V_command] = y;
}

Status model_do_step(Instance *comp, double t, double h) {
    Work *w = (Work *)comp->work;
    const double *A = &comp->r[VR_A_1_1], *B = &comp->r[VR_B_1], *Bx = &comp->r[VR_B_x_1];
    double e = error_signal(comp), xm = comp->r[VR_x_measured];
    int i, j, n = comp->i[VR_n], held = comp->i[VR_integral_index];
    (void)t;
    /* The matrices hold for one sample period only: another step size would silently change the controller. */
    if (fabs(h - comp->r[VR_h]) > 1e-9 + 1e-6 * comp->r[VR_h]) {
        fmu_log(comp, Error, "logStatusError", "communication step %g s differs from the controller's sample period h=%g s", h, comp->r[VR_h]);
        return Error;
    }
    if (!comp->b[VR_engaged]) {  /* held in reset until the supervisor engages it */
        memset(w->x, 0, sizeof(w->x));
        return OK;
    }
    for (i = 0; i < n; i++) {
        double s = B[i] * e;
        s += Bx[i] * xm;  /* 0 for a SISO G(s) */
        for (j = 0; j < n; j++) s += A[i * MAX_ORDER + j] * w->x[j];
        w->next[i] = s;
    }
    if (held > 0) {  /* a state feedback's integral, limited as in Quanser's lab */
        double limit = comp->r[VR_integral_limit];
        if (w->next[held - 1] > limit) w->next[held - 1] = limit;
        if (w->next[held - 1] < -limit) w->next[held - 1] = -limit;
    }
    memcpy(w->x, w->next, (size_t)n * sizeof(double));
    return OK;
}
