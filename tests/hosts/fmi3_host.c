/* A plain C FMI 3.0 host for the FMI 3.0 cart models (Plant3, Seesaw3), built natively (dlopen) and with mingw-w64
 * (LoadLibrary, run under Wine): the FMI 3.0 companion of fmu_host.c (issues 11 and 20).
 *
 * usage: fmi3_host LIB INSTANTIATION_TOKEN STEPS vr(V) vr(x) vr(xdot) vr(angle) vr(angledot) [CS_ANGLE ME_ANGLE]
 * (angle: the plant's alpha, the seesaw's theta; the start angles default to the plant's pi + 0.3 and pi - 0.3)
 * prints two lines of %.17g:
 *   1. Co-Simulation: the states after fmu_host.c's open-loop case (12 V sine from the angle CS_ANGLE,
 *      STEPS steps of 1 ms), so it can be compared with the FMI 2.0 FMU's line too;
 *   2. Model Exchange: the states after STEPS ms of explicit Euler (0.1 ms) from the angle ME_ANGLE with
 *      friction on and the default pulse (the poke or the tap, at 1 s), with an event iteration wherever an event
 *      indicator changes sign or a time event is due, then the number of state and time events. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "library.h"
#include "fmi3Functions.h"

#define PI 3.14159265358979323846
#define NX 4
#define NZ_MAX 64

typedef struct {
    fmi3InstantiateCoSimulationTYPE *instantiate_cs;
    fmi3InstantiateModelExchangeTYPE *instantiate_me;
    fmi3EnterInitializationModeTYPE *enter;
    fmi3ExitInitializationModeTYPE *leave;
    fmi3SetFloat64TYPE *set;
    fmi3GetFloat64TYPE *get;
    fmi3DoStepTYPE *do_step;
    fmi3GetNumberOfEventIndicatorsTYPE *number_of_indicators;
    fmi3UpdateDiscreteStatesTYPE *update;
    fmi3EnterEventModeTYPE *event_mode;
    fmi3EnterContinuousTimeModeTYPE *continuous_mode;
    fmi3SetTimeTYPE *set_time;
    fmi3GetContinuousStatesTYPE *get_x;
    fmi3SetContinuousStatesTYPE *set_x;
    fmi3GetContinuousStateDerivativesTYPE *get_dx;
    fmi3GetEventIndicatorsTYPE *get_z;
    fmi3TerminateTYPE *terminate;
    fmi3FreeInstanceTYPE *free_instance;
} Api;

static void logger(fmi3InstanceEnvironment e, fmi3Status s, fmi3String category, fmi3String message) {
    (void)e; (void)s;
    fprintf(stderr, "%s: %s\n", category, message);
}

#define LOAD(field, name) ok = ok && (api->field = (void *)symbol(lib, name)) != NULL
static int load(const char *path, Api *api) {
    Library lib = open_library(path);
    int ok = lib != NULL;
    LOAD(instantiate_cs, "fmi3InstantiateCoSimulation");
    LOAD(instantiate_me, "fmi3InstantiateModelExchange");
    LOAD(enter, "fmi3EnterInitializationMode");
    LOAD(leave, "fmi3ExitInitializationMode");
    LOAD(set, "fmi3SetFloat64");
    LOAD(get, "fmi3GetFloat64");
    LOAD(do_step, "fmi3DoStep");
    LOAD(number_of_indicators, "fmi3GetNumberOfEventIndicators");
    LOAD(update, "fmi3UpdateDiscreteStates");
    LOAD(event_mode, "fmi3EnterEventMode");
    LOAD(continuous_mode, "fmi3EnterContinuousTimeMode");
    LOAD(set_time, "fmi3SetTime");
    LOAD(get_x, "fmi3GetContinuousStates");
    LOAD(set_x, "fmi3SetContinuousStates");
    LOAD(get_dx, "fmi3GetContinuousStateDerivatives");
    LOAD(get_z, "fmi3GetEventIndicators");
    LOAD(terminate, "fmi3Terminate");
    LOAD(free_instance, "fmi3FreeInstance");
    return ok;
}

/* Event mode until the discrete states settle; returns the next time event (or a negative number). */
static double event_iteration(Api *api, fmi3Instance m) {
    fmi3Boolean again = fmi3True, terminate, nominals, values, defined = fmi3False;
    fmi3Float64 next = -1;
    while (again) {
        if (api->update(m, &again, &terminate, &nominals, &values, &defined, &next) != fmi3OK) exit(20);
    }
    return defined ? next : -1;
}

int main(int argc, char **argv) {
    Api api;
    fmi3ValueReference vr[5];
    fmi3Instance p;
    double v[NX], u, x[NX], dx[NX], z[NZ_MAX], z_old[NZ_MAX], t, h = 1e-4, next_time, cs_angle = PI + 0.3, me_angle = PI - 0.3;
    size_t nz, i;
    int k, n, state_events = 0, time_events = 0;
    if (argc != 9 && argc != 11) { fprintf(stderr, "usage: see fmi3_host.c\n"); return 2; }
    if (argc == 11) { cs_angle = atof(argv[9]); me_angle = atof(argv[10]); }
    if (!load(argv[1], &api)) { fprintf(stderr, "cannot load %s or one of its FMI 3.0 functions\n", argv[1]); return 3; }
    n = atoi(argv[3]);
    for (k = 0; k < 5; k++) vr[k] = (fmi3ValueReference)atoi(argv[4 + k]);

    /* 1. Co-Simulation: the plant alone, open loop (fmu_host.c's case 1) */
    p = api.instantiate_cs("model", argv[2], "", fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL, logger, NULL);
    if (!p) return 4;
    u = cs_angle;
    if (api.enter(p, fmi3False, 0, 0, fmi3False, 0) != fmi3OK || api.set(p, &vr[3], 1, &u, 1) != fmi3OK) return 5;
    if (api.leave(p) != fmi3OK) return 5;
    for (k = 0; k < n; k++) {
        fmi3Boolean event, stop, early;
        fmi3Float64 last;
        u = 12.0 * sin(2 * PI * k * 1e-3);
        api.set(p, &vr[0], 1, &u, 1);
        if (api.do_step(p, k * 1e-3, 1e-3, fmi3True, &event, &stop, &early, &last) != fmi3OK) return 6;
    }
    api.get(p, &vr[1], 4, v, 4);
    printf("%.17g %.17g %.17g %.17g\n", v[0], v[1], v[2], v[3]);
    api.terminate(p);
    api.free_instance(p);

    /* 2. Model Exchange: explicit Euler with state and time events (friction on, a poke) */
    p = api.instantiate_me("model", argv[2], "", fmi3False, fmi3False, NULL, logger);
    if (!p || api.number_of_indicators(p, &nz) != fmi3OK || nz > NZ_MAX) return 7;
    u = me_angle;
    if (api.enter(p, fmi3False, 0, 0, fmi3False, 0) != fmi3OK || api.set(p, &vr[3], 1, &u, 1) != fmi3OK) return 8;
    if (api.leave(p) != fmi3OK) return 8;
    next_time = event_iteration(&api, p);
    if (api.continuous_mode(p) != fmi3OK) return 9;
    api.get_z(p, z_old, nz);
    t = 0;
    for (k = 0; k < n * 10; k++) {
        int time_event;
        api.get_x(p, x, NX);
        api.get_dx(p, dx, NX);
        t = (k + 1) * h;
        time_event = next_time >= 0 && t >= next_time;
        for (i = 0; i < NX; i++) x[i] += h * dx[i];
        api.set_time(p, t);
        api.set_x(p, x, NX);
        api.get_z(p, z, nz);
        for (i = 0; i < nz && !time_event; i++) if ((z[i] > 0) != (z_old[i] > 0)) break;
        if (time_event || i < nz) {
            if (time_event) time_events++; else state_events++;
            api.event_mode(p);
            next_time = event_iteration(&api, p);
            api.continuous_mode(p);
            api.get_z(p, z, nz);
        }
        memcpy(z_old, z, nz * sizeof(double));
    }
    api.get(p, &vr[1], 4, v, 4);
    printf("%.17g %.17g %.17g %.17g %d %d\n", v[0], v[1], v[2], v[3], state_events, time_events);
    api.terminate(p);
    api.free_instance(p);
    return 0;
}
