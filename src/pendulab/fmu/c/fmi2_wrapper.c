/* The FMI 2.0 API of every pendulab FMU (Model Exchange and Co-Simulation).
 *
 * The logic is fmu_common.c's, shared with fmi3_wrapper.c; this file translates: FMI 2.0's types and
 * function names, its callbacks (the logger), its value references (the model's own: one array per base
 * type) and the results only FMI 2.0 has (fmi2EventInfo, the status functions). */
#include <stdlib.h>

#include "fmi2Functions.h"
#include "fmu_common.h"

/* The model's instance, then what only this wrapper needs. */
typedef struct {
    Instance model;
    fmi2CallbackFunctions callbacks;
} Component;

/* Status has fmi2Status's order. */
#define STATUS(status) ((fmi2Status)(status))
#define COMP ((Instance *)c)

void fmu_log_message(Instance *comp, Status status, const char *category, const char *message) {
    const fmi2CallbackFunctions *callbacks = &((Component *)comp)->callbacks;
    if (callbacks->logger)
        callbacks->logger(callbacks->componentEnvironment, comp->instance_name, STATUS(status), category, "%s", message);
}

/* ------------------------------------------------------------------ inquire and log */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[]) {
    UNUSED(nCategories); UNUSED(categories);
    return STATUS(fmu_set_debug_logging(COMP, loggingOn));
}

/* ------------------------------------------------------------------ life cycle */
fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    Component *component;
    UNUSED(fmuResourceLocation); UNUSED(visible);
    if (!functions || !instanceName || !fmuGUID) return NULL;
    component = (Component *)calloc(1, sizeof(Component));
    if (!component) return NULL;
    component->callbacks = *functions;
    if (fmu_instantiate(&component->model, "fmi2Instantiate", instanceName, fmuGUID,
                        fmuType == fmi2ModelExchange ? ModelExchange : CoSimulation, loggingOn) != OK) {
        free(component);
        return NULL;
    }
    return component;
}

void fmi2FreeInstance(fmi2Component c) {
    fmu_free_instance(COMP);
    free(c);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    UNUSED(toleranceDefined); UNUSED(tolerance); UNUSED(stopTimeDefined); UNUSED(stopTime);
    return STATUS(fmu_setup_experiment(COMP, "fmi2SetupExperiment", startTime));
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    return STATUS(fmu_enter_initialization_mode(COMP, "fmi2EnterInitializationMode"));
}
fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    return STATUS(fmu_exit_initialization_mode(COMP, "fmi2ExitInitializationMode"));
}
fmi2Status fmi2Terminate(fmi2Component c) { return STATUS(fmu_terminate(COMP, "fmi2Terminate")); }
fmi2Status fmi2Reset(fmi2Component c) { return STATUS(fmu_reset(COMP, "fmi2Reset")); }

/* ------------------------------------------------------------------ variables */
/* FMI 2.0's value references are the indices in the model's arrays. */
#define GETTER(Name, Type, array, Array)                                                                   \
    fmi2Status Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, Type value[]) {           \
        size_t k;                                                                                         \
        if (fmu_begin_get(COMP, #Name, vr, nvr, value, nvr) != OK) return fmi2Error;                      \
        for (k = 0; k < nvr; k++) {                                                                       \
            long index = fmu_index(COMP, #Name, Array, vr[k], 0, 0);                                      \
            if (index < 0) return fmi2Error;                                                              \
            value[k] = COMP->array[index];                                                                \
        }                                                                                                 \
        return fmi2OK;                                                                                    \
    }

#define SETTER(Name, Type, array, Array)                                                                   \
    fmi2Status Name(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const Type value[]) {     \
        size_t k;                                                                                         \
        if (fmu_begin_set(COMP, #Name, vr, nvr, value, nvr) != OK) return fmi2Error;                      \
        for (k = 0; k < nvr; k++) {                                                                       \
            long index = fmu_index(COMP, #Name, Array, vr[k], 0, 1);                                      \
            if (index < 0) return fmi2Error;                                                              \
            if (fmu_check_value(COMP, #Name, Array, index, (double)value[k]) != OK) return fmi2Error;     \
            COMP->array[index] = value[k];                                                                \
        }                                                                                                 \
        return fmi2OK;                                                                                    \
    }

GETTER(fmi2GetReal, fmi2Real, r, REALS)
GETTER(fmi2GetInteger, fmi2Integer, i, INTEGERS)
GETTER(fmi2GetBoolean, fmi2Boolean, b, BOOLEANS)
SETTER(fmi2SetReal, fmi2Real, r, REALS)
SETTER(fmi2SetInteger, fmi2Integer, i, INTEGERS)
SETTER(fmi2SetBoolean, fmi2Boolean, b, BOOLEANS)

fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    UNUSED(vr); UNUSED(value);
    return STATUS(fmu_no_variables(COMP, "fmi2GetString", nvr));
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    UNUSED(vr); UNUSED(value);
    return STATUS(fmu_no_variables(COMP, "fmi2SetString", nvr));
}

/* ------------------------------------------------------------------ unsupported optional features */
#define NOT_SUPPORTED(what) return STATUS(fmu_not_supported(COMP, what))

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
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    return STATUS(fmu_do_step(COMP, "fmi2DoStep", currentCommunicationPoint, communicationStepSize));
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) { UNUSED(s); UNUSED(value); NOT_SUPPORTED("fmi2GetStatus"); }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    if (s == fmi2LastSuccessfulTime && c && value) { *value = COMP->time; return fmi2OK; }
    NOT_SUPPORTED("this status kind");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) { UNUSED(s); UNUSED(value); NOT_SUPPORTED("fmi2GetIntegerStatus"); }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) { UNUSED(s); UNUSED(value); NOT_SUPPORTED("fmi2GetBooleanStatus"); }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) { UNUSED(s); UNUSED(value); NOT_SUPPORTED("fmi2GetStringStatus"); }

/* ------------------------------------------------------------------ Model Exchange */
fmi2Status fmi2EnterEventMode(fmi2Component c) { return STATUS(fmu_enter_event_mode(COMP, "fmi2EnterEventMode")); }

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *info) {
    int states_changed;
    double next;
    Status status = fmu_update_discrete_states(COMP, "fmi2NewDiscreteStates", &states_changed, &next);
    if (info) {
        info->newDiscreteStatesNeeded = fmi2False;
        info->terminateSimulation = fmi2False;
        info->nominalsOfContinuousStatesChanged = fmi2False;
        info->valuesOfContinuousStatesChanged = states_changed ? fmi2True : fmi2False;
        info->nextEventTimeDefined = next >= 0 ? fmi2True : fmi2False;
        info->nextEventTime = next >= 0 ? next : 0;
    }
    return STATUS(status);
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    return STATUS(fmu_enter_continuous_time_mode(COMP, "fmi2EnterContinuousTimeMode"));
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    if (enterEventMode) *enterEventMode = fmi2False;
    if (terminateSimulation) *terminateSimulation = fmi2False;
    return STATUS(fmu_completed_integrator_step(COMP, "fmi2CompletedIntegratorStep"));
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) { return STATUS(fmu_set_time(COMP, "fmi2SetTime", time)); }

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    return STATUS(fmu_set_continuous_states(COMP, "fmi2SetContinuousStates", x, nx));
}
fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    return STATUS(fmu_get_derivatives(COMP, "fmi2GetDerivatives", derivatives, nx));
}
fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    return STATUS(fmu_get_event_indicators(COMP, "fmi2GetEventIndicators", eventIndicators, ni));
}
fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real states[], size_t nx) {
    return STATUS(fmu_get_continuous_states(COMP, "fmi2GetContinuousStates", states, nx));
}
fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    return STATUS(fmu_get_nominals(COMP, "fmi2GetNominalsOfContinuousStates", x_nominal, nx));
}
