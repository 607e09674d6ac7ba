/* A plain C FMI 2.0 co-simulation host, built natively (dlopen) and with mingw-w64 (LoadLibrary, run
 * under Wine): the same reference cases on both platforms' binaries (issue 11).
 *
 * usage: fmu_host PLANT_LIB PLANT_GUID CONTROLLER_LIB CONTROLLER_GUID STEPS
 *        vr(V) vr(x) vr(xdot) vr(alpha) vr(alphadot) vr(alpha_measured)
 *        vr(ctl.alpha_measured) vr(ctl.V_command) vr(ctl.n) vr(ctl.A[1,1]) vr(ctl.B[1]) vr(ctl.C[1]) vr(ctl.D)
 * prints two lines of %.17g: the plant's states after the open-loop case (12 V sine from alpha = pi + 0.3),
 * then the plant's states and the controller's output after the closed loop of plant and controller. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#ifdef _WIN32
#include <windows.h>
typedef HMODULE Library;
static Library open_library(const char *path) { return LoadLibraryA(path); }
static void *symbol(Library lib, const char *name) { return (void *)GetProcAddress(lib, name); }
#else
#include <dlfcn.h>
typedef void *Library;
static Library open_library(const char *path) { return dlopen(path, RTLD_NOW | RTLD_LOCAL); }
static void *symbol(Library lib, const char *name) { return dlsym(lib, name); }
#endif
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
    Api plant, ctl;
    fmi2ValueReference vr[13];
    fmi2Component p, c;
    double v[4], u, y, one = 1.0;
    int k, n;
    if (argc != 19) { fprintf(stderr, "usage: see fmu_host.c\n"); return 2; }
    if (!load(argv[1], &plant) || !load(argv[3], &ctl)) { fprintf(stderr, "cannot load a library\n"); return 3; }
    n = atoi(argv[5]);
    for (k = 0; k < 13; k++) vr[k] = (fmi2ValueReference)atoi(argv[6 + k]);

    /* 1. the plant alone, open loop */
    p = start(&plant, "plant", argv[2], vr[3], PI + 0.3);
    if (!p || plant.leave(p) != fmi2OK) return 4;
    for (k = 0; k < n; k++) {
        u = 12.0 * sin(2 * PI * k * 1e-3);
        plant.set_real(p, &vr[0], 1, &u);
        if (plant.do_step(p, k * 1e-3, 1e-3, fmi2True) != fmi2OK) return 5;
    }
    plant.get_real(p, &vr[1], 4, v);
    printf("%.17g %.17g %.17g %.17g\n", v[0], v[1], v[2], v[3]);
    plant.free_instance(p);

    /* 2. plant and controller in a loop: x+ = 0.5 x + e, V = 2 x + 3 e, e = -Lp alpha_measured */
    p = start(&plant, "plant", argv[2], vr[3], PI + 0.3);
    c = start(&ctl, "controller", argv[4], vr[9], 0.5);
    if (!p || !c) return 6;
    {
        fmi2Integer order = 1;
        double b = 1.0, cc = 2.0, d = 3.0;
        ctl.set_integer(c, &vr[8], 1, &order);
        ctl.set_real(c, &vr[10], 1, &b);
        ctl.set_real(c, &vr[11], 1, &cc);
        ctl.set_real(c, &vr[12], 1, &d);
    }
    (void)one;
    if (plant.leave(p) != fmi2OK || ctl.leave(c) != fmi2OK) return 7;
    for (k = 0; k < n; k++) {
        plant.get_real(p, &vr[5], 1, &y);
        ctl.set_real(c, &vr[6], 1, &y);
        ctl.get_real(c, &vr[7], 1, &u);
        plant.set_real(p, &vr[0], 1, &u);
        if (ctl.do_step(c, k * 1e-3, 1e-3, fmi2True) != fmi2OK) return 8;
        if (plant.do_step(p, k * 1e-3, 1e-3, fmi2True) != fmi2OK) return 9;
    }
    plant.get_real(p, &vr[1], 4, v);
    ctl.get_real(c, &vr[7], 1, &u);
    printf("%.17g %.17g %.17g %.17g %.17g\n", v[0], v[1], v[2], v[3], u);
    plant.free_instance(p);
    ctl.free_instance(c);
    return 0;
}
