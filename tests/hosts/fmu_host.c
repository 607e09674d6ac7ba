/* A plain C FMI 2.0 co-simulation host, built natively (dlopen) and with mingw-w64 (LoadLibrary, run
 * under Wine): the same reference cases on both platforms' binaries (issue 11).
 *
 * usage: fmu_host PLANT_LIB PLANT_GUID CONTROLLER_LIB CONTROLLER_GUID SUPERVISOR_LIB SUPERVISOR_GUID STEPS
 *        vr(V) vr(x) vr(xdot) vr(alpha) vr(alphadot) vr(alpha_measured) vr(x_measured)
 *        vr(ctl.alpha_measured) vr(ctl.V_command) vr(ctl.n) vr(ctl.A[1,1]) vr(ctl.B[1]) vr(ctl.C[1]) vr(ctl.D)
 *        vr(sup.V_command) vr(sup.alpha_measured) vr(sup.x_measured) vr(sup.V) [OPEN_ANGLE LOOP_ANGLE]
 * prints two lines of %.17g: the plant's states after the open-loop case (12 V sine from alpha = OPEN_ANGLE,
 * default pi + 0.3), then the plant's states, the controller's and the supervisor's voltage after the closed loop
 * of the three FMUs (wired as pendulab.cosim.pendulum.CONNECTIONS, from alpha = LOOP_ANGLE, default 0.01 near
 * upright). The seesaw takes the plant's place with its tilt theta as the angle (the vr arguments say which). */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include "library.h"
#include "fmi2Functions.h"

#define PI 3.14159265358979323846

typedef struct {
    fmi2InstantiateTYPE *instantiate;
    fmi2SetupExperimentTYPE *setup;
    fmi2EnterInitializationModeTYPE *enter;
    fmi2ExitInitializationModeTYPE *leave;
    fmi2SetRealTYPE *set_real;
    fmi2GetRealTYPE *get_real;
    fmi2SetIntegerTYPE *set_integer;
    fmi2DoStepTYPE *do_step;
    fmi2FreeInstanceTYPE *free_instance;
} Api;

static void logger(fmi2ComponentEnvironment e, fmi2String name, fmi2Status s, fmi2String c, fmi2String m, ...) {
    (void)e; (void)s; (void)c;
    fprintf(stderr, "%s: %s\n", name, m);
}

static int load(const char *path, Api *api) {
    Library lib = open_library(path);
    if (!lib) return 0;
    api->instantiate = (fmi2InstantiateTYPE *)symbol(lib, "fmi2Instantiate");
    api->setup = (fmi2SetupExperimentTYPE *)symbol(lib, "fmi2SetupExperiment");
    api->enter = (fmi2EnterInitializationModeTYPE *)symbol(lib, "fmi2EnterInitializationMode");
    api->leave = (fmi2ExitInitializationModeTYPE *)symbol(lib, "fmi2ExitInitializationMode");
    api->set_real = (fmi2SetRealTYPE *)symbol(lib, "fmi2SetReal");
    api->get_real = (fmi2GetRealTYPE *)symbol(lib, "fmi2GetReal");
    api->set_integer = (fmi2SetIntegerTYPE *)symbol(lib, "fmi2SetInteger");
    api->do_step = (fmi2DoStepTYPE *)symbol(lib, "fmi2DoStep");
    api->free_instance = (fmi2FreeInstanceTYPE *)symbol(lib, "fmi2FreeInstance");
    return api->instantiate && api->do_step && api->free_instance;
}

static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

static fmi2Component start(Api *api, const char *name, const char *guid, fmi2ValueReference vr, double value) {
    fmi2Component c = api->instantiate(name, fmi2CoSimulation, guid, "", &callbacks, fmi2False, fmi2False);
    if (!c) return NULL;
    api->setup(c, fmi2False, 0, 0, fmi2False, 0);
    api->enter(c);
    api->set_real(c, &vr, 1, &value);
    return c;
}

int main(int argc, char **argv) {
    Api plant, ctl, sup;
    fmi2ValueReference vr[18];
    fmi2Component p, c, s;
    double v[4], u, y, xm, w, open_angle = PI + 0.3, loop_angle = 0.01;
    int k, n;
    if (argc != 26 && argc != 28) { fprintf(stderr, "usage: see fmu_host.c\n"); return 2; }
    if (argc == 28) { open_angle = atof(argv[26]); loop_angle = atof(argv[27]); }
    if (!load(argv[1], &plant) || !load(argv[3], &ctl) || !load(argv[5], &sup)) {
        fprintf(stderr, "cannot load a library\n");
        return 3;
    }
    n = atoi(argv[7]);
    for (k = 0; k < 18; k++) vr[k] = (fmi2ValueReference)atoi(argv[8 + k]);

    /* 1. the plant alone, open loop */
    p = start(&plant, "plant", argv[2], vr[3], open_angle);
    if (!p || plant.leave(p) != fmi2OK) return 4;
    for (k = 0; k < n; k++) {
        u = 12.0 * sin(2 * PI * k * 1e-3);
        plant.set_real(p, &vr[0], 1, &u);
        if (plant.do_step(p, k * 1e-3, 1e-3, fmi2True) != fmi2OK) return 5;
    }
    plant.get_real(p, &vr[1], 4, v);
    printf("%.17g %.17g %.17g %.17g\n", v[0], v[1], v[2], v[3]);
    plant.free_instance(p);

    /* 2. the three FMUs in a loop: x+ = 0.9 x + e, V = 20 x + 30 e, e = -Lp alpha_measured */
    p = start(&plant, "plant", argv[2], vr[3], loop_angle);
    c = start(&ctl, "controller", argv[4], vr[10], 0.9);
    s = start(&sup, "supervisor", argv[6], vr[14], 0.0);
    if (!p || !c || !s) return 6;
    {
        fmi2Integer order = 1;
        double b = 1.0, cc = 20.0, d = 30.0;
        ctl.set_integer(c, &vr[9], 1, &order);
        ctl.set_real(c, &vr[11], 1, &b);
        ctl.set_real(c, &vr[12], 1, &cc);
        ctl.set_real(c, &vr[13], 1, &d);
    }
    if (plant.leave(p) != fmi2OK || ctl.leave(c) != fmi2OK || sup.leave(s) != fmi2OK) return 7;
    for (k = 0; k < n; k++) {
        plant.get_real(p, &vr[5], 1, &y);
        plant.get_real(p, &vr[6], 1, &xm);
        ctl.set_real(c, &vr[7], 1, &y);
        sup.set_real(s, &vr[15], 1, &y);
        sup.set_real(s, &vr[16], 1, &xm);
        ctl.get_real(c, &vr[8], 1, &u);
        sup.set_real(s, &vr[14], 1, &u);
        sup.get_real(s, &vr[17], 1, &w);
        plant.set_real(p, &vr[0], 1, &w);
        if (ctl.do_step(c, k * 1e-3, 1e-3, fmi2True) != fmi2OK) return 8;
        if (sup.do_step(s, k * 1e-3, 1e-3, fmi2True) != fmi2OK) return 9;
        if (plant.do_step(p, k * 1e-3, 1e-3, fmi2True) != fmi2OK) return 10;
    }
    plant.get_real(p, &vr[1], 4, v);
    ctl.get_real(c, &vr[8], 1, &u);
    sup.get_real(s, &vr[17], 1, &w);
    printf("%.17g %.17g %.17g %.17g %.17g %.17g\n", v[0], v[1], v[2], v[3], u, w);
    plant.free_instance(p);
    ctl.free_instance(c);
    sup.free_instance(s);
    return 0;
}
