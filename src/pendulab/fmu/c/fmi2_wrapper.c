/* The one FMI 2.0 wrapper shared by all pendulab FMUs (Model Exchange and Co-Simulation).
 *
 * It owns the life cycle, the mode checks, the variable access by value reference and the logging;
 * each model supplies its equations through fmu_model.h (shared with fmi3_wrapper.c). */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_model.h"

/* The model's instance, then what only this wrapper needs. */
typedef struct {
    Instance model;
    fmi2CallbackFunctions callbacks;
} Component;

#define UNUSED(x) (void)(x)

void fmu_log(Instance *comp, Status status, const char *category, const char *message, ...) {
    char buffer[1024];
    va_list args;
    const fmi2CallbackFunctions *callbacks = comp ? &((Component *)comp)->callbacks : NULL;
    if (!callbacks || !callbacks->logger) return;
    if (!comp->logging_on && status == OK) return;
    va_start(args, message);
    vsnprintf(buffer, sizeof(buffer), message, args);
    va_end(args);
    callbacks->logger(callbacks->componentEnvironment, comp->instance_name, (fmi2Status)status, category, "%s", buffer);
}

static int in_mode(Instance *comp, const char *function, int allowed) {
    if (!comp) return 0;
    if (allowed & (1 << comp->mode)) return 1;
    fmu_log(comp, Error, "logStatusError", "%s must not be called in the current state (mode %d)", function, (int)comp->mode);
    return 0;
}

#define M(mode) (1 << (mode))
#define ANY_MODE (M(MODE_INSTANTIATED) | M(MODE_INITIALIZATION) | M(MODE_STEP) | M(MODE_EVENT) | M(MODE_CONTINUOUS) | M(MODE_TERMINATED))
#define CHECK(function, allowed) \
    do { if (!in_mode(comp, function, allowed)) return fmi2Error; } while (0)

/* ------------------------------------------------------------------ inquire and log */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[]) {
    Instance *comp = (Instance *)c;
    UNUSED(nCategories); UNUSED(categories);
    if (!comp) return fmi2Error;
    comp->logging_on = loggingOn;
    return fmi2OK;
}

/* ------------------------------------------------------------------ life cycle */
static void set_start_values(Instance *comp) {
    int k;
    for (k = 0; k < N_REALS; k++) comp->r[k] = REAL_START[k];
    for (k = 0; k < N_INTEGERS; k++) comp->i[k] = INTEGER_START[k];
    for (k = 0; k < N_BOOLEANS; k++) comp->b[k] = BOOLEAN_START[k];
    model_reset(comp);
    comp->outputs_stale = 1;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    Component *component;
    Instance *comp;
    UNUSED(fmuResourceLocation); UNUSED(visible);
    if (!functions || !instanceName || !fmuGUID) return NULL;
    if (strcmp(fmuGUID, MODEL_GUID) != 0) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                              "wrong GUID %s, expected %s: the modelDescription.xml does not belong to this binary",
                              fmuGUID, MODEL_GUID);
        return NULL;
    }
#if N_STATES == 0
    if (fmuType == fmi2ModelExchange) {
        if (functions->logger)
            functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                              "%s supports Co-Simulation only", MODEL_NAME);
        return NULL;
    }
#endif
    component = (Component *)calloc(1, sizeof(Component));
    if (!component) return NULL;
    comp = &component->model;
    comp->instance_name = (const char *)malloc(strlen(instanceName) + 1);
    if (!comp->instance_name) { free(component); return NULL; }
    strcpy((char *)comp->instance_name, instanceName);
    component->callbacks = *functions;
    comp->type = fmuType == fmi2ModelExchange ? ModelExchange : CoSimulation;
    comp->logging_on = loggingOn;
    comp->work = model_work_size() ? calloc(1, model_work_size()) : NULL;
    if (model_work_size() && !comp->work) {
        free((void *)comp->instance_name);
        free(component);
        return NULL;
    }
    comp->mode = MODE_INSTANTIATED;
    set_start_values(comp);
    return comp;
}

void fmi2FreeInstance(fmi2Component c) {
    Instance *comp = (Instance *)c;
    if (!comp) return;
    free(comp->work);
    free((void *)comp->instance_name);
    free((Component *)comp);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Instance *comp = (Instance *)c;
    UNUSED(toleranceDefined); UNUSED(tolerance); UNUSED(stopTimeDefined); UNUSED(stopTime);
    CHECK("fmi2SetupExperiment", M(MODE_INSTANTIATED));
    comp->time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2EnterInitializationMode", M(MODE_INSTANTIATED));
    comp->mode = MODE_INITIALIZATION;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Instance *comp = (Instance *)c;
    Status status;
    CHECK("fmi2ExitInitializationMode", M(MODE_INITIALIZATION));
    status = model_initialize(comp);
    if (status > Warning) return (fmi2Status)status;
    comp->outputs_stale = 1;
    comp->mode = comp->type == CoSimulation ? MODE_STEP : MODE_EVENT;
    return (fmi2Status)status;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2Terminate", M(MODE_STEP) | M(MODE_EVENT) | M(MODE_CONTINUOUS));
    comp->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2Reset", ANY_MODE);
    comp->time = 0;
    comp->mode = MODE_INSTANTIATED;
    if (comp->work) memset(comp->work, 0, model_work_size());
    set_start_values(comp);
    return fmi2OK;
}

/* ------------------------------------------------------------------ variables */
static void refresh(Instance *comp) {
    if (comp->outputs_stale) {
        model_update_outputs(comp);
        comp->outputs_stale = 0;
    }
}

#define GETTER(Name, Type, array, count)                                                                   \
    fmi2Status Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, Type value[]) {           \
        Instance *comp = (Instance *)c;                                                                   \
        size_t k;                                                                                         \
        CHECK(#Name, ANY_MODE);                            \
        if (nvr > 0 && (!vr || !value)) return fmi2Error;                                                 \
        if (comp->mode != MODE_INSTANTIATED) refresh(comp);                                               \
        for (k = 0; k < nvr; k++) {                                                                       \
            if (vr[k] >= (count)) {                                                                       \
                fmu_log(comp, Error, "logStatusError", #Name ": unknown value reference %u", vr[k]);  \
                return fmi2Error;                                                                         \
            }                                                                                             \
            value[k] = comp->array[vr[k]];                                                                \
        }                                                                                                 \
        return fmi2OK;                                                                                    \
    }

#define SETTER(Name, Type, array, count, fixed)                                                            \
    fmi2Status Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const Type value[]) {     \
        Instance *comp = (Instance *)c;                                                                   \
        size_t k;                                                                                         \
        int initialized;                                                                                  \
        CHECK(#Name, M(MODE_INSTANTIATED) | M(MODE_INITIALIZATION) | M(MODE_STEP) | M(MODE_EVENT) |      \
                         M(MODE_CONTINUOUS));                                                             \
        if (nvr > 0 && (!vr || !value)) return fmi2Error;                                                 \
        initialized = comp->mode != MODE_INSTANTIATED && comp->mode != MODE_INITIALIZATION;               \
        for (k = 0; k < nvr; k++) {                                                                       \
            if (vr[k] >= (count)) {                                                                       \
                fmu_log(comp, Error, "logStatusError", #Name ": unknown value reference %u", vr[k]);  \
                return fmi2Error;                                                                         \
            }                                                                                             \
            if (initialized && fixed[vr[k]]) {                                                            \
                fmu_log(comp, Error, "logStatusError",                                               \
                        #Name ": value reference %u is a fixed parameter; set it before initialization",  \
                        vr[k]);                                                                           \
                return fmi2Error;                                                                         \
            }                                                                                             \
            comp->array[vr[k]] = value[k];                                                                \
        }                                                                                                 \
        comp->outputs_stale = 1;                                                                          \
        return fmi2OK;                                                                                    \
    }

GETTER(fmi2GetReal, fmi2Real, r, N_REALS)
GETTER(fmi2GetInteger, fmi2Integer, i, N_INTEGERS)
GETTER(fmi2GetBoolean, fmi2Boolean, b, N_BOOLEANS)
SETTER(fmi2SetReal, fmi2Real, r, N_REALS, REAL_FIXED)
SETTER(fmi2SetInteger, fmi2Integer, i, N_INTEGERS, INTEGER_FIXED)
SETTER(fmi2SetBoolean, fmi2Boolean, b, N_BOOLEANS, BOOLEAN_FIXED)

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    Instance *comp = (Instance *)c;
    UNUSED(vr); UNUSED(value);
    if (nvr == 0) return fmi2OK;
    fmu_log(comp, Error, "logStatusError", "fmi2GetString: this model has no String variables");
    return fmi2Error;
}

fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    return fmi2GetString(c, vr, nvr, (fmi2String *)value);
}

/* ------------------------------------------------------------------ unsupported optional features */
#define NOT_SUPPORTED(what)                                                                                \
    do {                                                                                                  \
        fmu_log((Instance *)c, Error, "logStatusError", what " is not supported by this FMU");        \
        return fmi2Error;                                                                                 \
    } while (0)

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) { UNUSED(s); NOT_SUPPORTED("fmi2GetFMUstate"); }
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { UNUSED(s); NOT_SUPPORTED("fmi2SetFMUstate"); }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { UNUSED(s); NOT_SUPPORTED("fmi2FreeFMUstate"); }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { UNUSED(s); UNUSED(n); NOT_SUPPORTED("fmi2SerializedFMUstateSize"); }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { UNUSED(s); UNUSED(b); UNUSED(n); NOT_SUPPORTED("fmi2SerializeFMUstate"); }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) { UNUSED(b); UNUSED(n); UNUSED(s); NOT_SUPPORTED("fmi2DeSerializeFMUstate"); }
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu, const fmi2ValueReference z[],
                                        size_t nz, const fmi2Real du[], fmi2Real dz[]) {
    UNUSED(u); UNUSED(nu); UNUSED(z); UNUSED(nz); UNUSED(du); UNUSED(dz);
    NOT_SUPPORTED("fmi2GetDirectionalDerivative");
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer order[], const fmi2Real value[]) {
    UNUSED(vr); UNUSED(nvr); UNUSED(order); UNUSED(value);
    NOT_SUPPORTED("fmi2SetRealInputDerivatives");
}
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer order[], fmi2Real value[]) {
    UNUSED(vr); UNUSED(nvr); UNUSED(order); UNUSED(value);
    NOT_SUPPORTED("fmi2GetRealOutputDerivatives");
}
fmi2Status fmi2CancelStep(fmi2Component c) { NOT_SUPPORTED("fmi2CancelStep"); }

/* ------------------------------------------------------------------ Co-Simulation */
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Instance *comp = (Instance *)c;
    Status status;
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    CHECK("fmi2DoStep", M(MODE_STEP));
    if (communicationStepSize <= 0) {
        fmu_log(comp, Error, "logStatusError", "fmi2DoStep: step size %g must be positive", communicationStepSize);
        return fmi2Error;
    }
    status = model_do_step(comp, currentCommunicationPoint, communicationStepSize);
    comp->time = currentCommunicationPoint + communicationStepSize;
    comp->outputs_stale = 1;
    return (fmi2Status)status;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) { UNUSED(s); UNUSED(value); NOT_SUPPORTED("fmi2GetStatus"); }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    Instance *comp = (Instance *)c;
    if (s == fmi2LastSuccessfulTime && comp && value) { *value = comp->time; return fmi2OK; }
    NOT_SUPPORTED("this status kind");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) { UNUSED(s); UNUSED(value); NOT_SUPPORTED("fmi2GetIntegerStatus"); }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) { UNUSED(s); UNUSED(value); NOT_SUPPORTED("fmi2GetBooleanStatus"); }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) { UNUSED(s); UNUSED(value); NOT_SUPPORTED("fmi2GetStringStatus"); }

/* ------------------------------------------------------------------ Model Exchange */
fmi2Status fmi2EnterEventMode(fmi2Component c) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2EnterEventMode", M(MODE_EVENT) | M(MODE_CONTINUOUS));
    comp->mode = MODE_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2NewDiscreteStates", M(MODE_EVENT));
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0;
#if N_EVENT_INDICATORS > 0
    {
        int states_changed = 0;
        Status status = model_event_update(comp, &states_changed);
        if (status > Warning) return (fmi2Status)status;
        info->valuesOfContinuousStatesChanged = states_changed ? fmi2True : fmi2False;
    }
#endif
#if N_STATES > 0
    {
        double next = model_next_time_event(comp);
        if (next >= 0) {
            info->nextEventTimeDefined = fmi2True;
            info->nextEventTime = next;
        }
    }
#endif
    comp->outputs_stale = 1;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2EnterContinuousTimeMode", M(MODE_EVENT));
    comp->mode = MODE_CONTINUOUS;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    Instance *comp = (Instance *)c;
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    CHECK("fmi2CompletedIntegratorStep", M(MODE_CONTINUOUS));
    *enterEventMode = fmi2False;
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2SetTime", M(MODE_EVENT) | M(MODE_CONTINUOUS));
    comp->time = time;
    comp->outputs_stale = 1;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2SetContinuousStates", M(MODE_CONTINUOUS));
#if N_STATES > 0
    if (nx != N_STATES) return fmi2Error;
    model_set_states(comp, x);
    comp->outputs_stale = 1;
    return fmi2OK;
#else
    UNUSED(x); UNUSED(nx);
    return fmi2Error;
#endif
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2GetDerivatives", M(MODE_INITIALIZATION) | M(MODE_EVENT) | M(MODE_CONTINUOUS) | M(MODE_TERMINATED));
#if N_STATES > 0
    if (nx != N_STATES) return fmi2Error;
    model_get_derivatives(comp, derivatives);
    return fmi2OK;
#else
    UNUSED(derivatives); UNUSED(nx);
    return fmi2Error;
#endif
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2GetEventIndicators", M(MODE_INITIALIZATION) | M(MODE_EVENT) | M(MODE_CONTINUOUS) | M(MODE_TERMINATED));
    if (ni != N_EVENT_INDICATORS) {
        fmu_log(comp, Error, "logStatusError", "fmi2GetEventIndicators: %u indicators asked, the model has %d",
                (unsigned)ni, N_EVENT_INDICATORS);
        return fmi2Error;
    }
#if N_EVENT_INDICATORS > 0
    model_get_event_indicators(comp, eventIndicators);
#else
    UNUSED(eventIndicators);
#endif
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real states[], size_t nx) {
    Instance *comp = (Instance *)c;
    CHECK("fmi2GetContinuousStates", M(MODE_INITIALIZATION) | M(MODE_EVENT) | M(MODE_CONTINUOUS) | M(MODE_TERMINATED));
#if N_STATES > 0
    if (nx != N_STATES) return fmi2Error;
    model_get_states(comp, states);
    return fmi2OK;
#else
    UNUSED(states); UNUSED(nx);
    return fmi2Error;
#endif
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    Instance *comp = (Instance *)c;
    size_t k;
    CHECK("fmi2GetNominalsOfContinuousStates", ANY_MODE);
    for (k = 0; k < nx; k++) x_nominal[k] = 1.0;
    return fmi2OK;
}
