/* The FMI 3.0 API of the FMI 3.0 pendulab FMUs (Model Exchange and Co-Simulation).
 *
 * As in the Modelica Reference-FMUs, one model (model.c, through fmu_model.h) and one implementation of the
 * FMI logic (fmu_common.c) serve both FMI versions; this file, like fmi2_wrapper.c, only translates: the
 * instantiate functions, value references unique across types (Float64, Int32, Boolean, then time and the
 * event indicators: see variables.h, VR3_...), the array-aware getters and setters, and the results only
 * FMI 3.0 has (fmi3UpdateDiscreteStates' and fmi3DoStep's). Scheduled Execution, clocks, FMU states and
 * directional derivatives are not offered (the modelDescription.xml says so) and answer with an error. */
#include <stdlib.h>

#include "fmi3Functions.h"
#include "fmu_common.h"

/* The model's instance, then what only this wrapper needs. */
typedef struct {
    Instance model;
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback logger;
} Component;

/* Status has fmi3Status's order. */
#define STATUS(status) ((fmi3Status)(status))
#define COMP ((Instance *)instance)
#define NOT_SUPPORTED(what) return STATUS(fmu_not_supported(COMP, what))

void fmu_log_message(Instance *comp, Status status, const char *category, const char *message) {
    Component *component = (Component *)comp;
    if (component->logger) component->logger(component->environment, STATUS(status), category, message);
}

/* ------------------------------------------------------------------ inquire and log */
const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories, const fmi3String categories[]) {
    UNUSED(nCategories); UNUSED(categories);
    return STATUS(fmu_set_debug_logging(COMP, loggingOn));
}

/* ------------------------------------------------------------------ life cycle */
static fmi3Instance instantiate(const char *function, fmi3String instanceName, InterfaceType type, fmi3String instantiationToken,
                                fmi3Boolean loggingOn, fmi3InstanceEnvironment environment, fmi3LogMessageCallback logger) {
    Component *component;
    if (!instanceName || !instantiationToken) return NULL;
    component = (Component *)calloc(1, sizeof(Component));
    if (!component) return NULL;
    component->environment = environment;
    component->logger = logger;
    if (fmu_instantiate(&component->model, function, instanceName, instantiationToken, type, loggingOn) != OK) {
        free(component);
        return NULL;
    }
    return component;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
                                          fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    UNUSED(resourcePath); UNUSED(visible);
    return instantiate("fmi3InstantiateModelExchange", instanceName, ModelExchange, instantiationToken, loggingOn,
                       instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
                                         fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
                                         fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    UNUSED(resourcePath); UNUSED(visible); UNUSED(earlyReturnAllowed); UNUSED(requiredIntermediateVariables);
    UNUSED(intermediateUpdate);
    /* hasEventMode="false" and no intermediate variables: the importer may not ask for either. */
    if (eventModeUsed || nRequiredIntermediateVariables > 0) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "Co-Simulation without event mode and without intermediate variables only (hasEventMode=\"false\")");
        return NULL;
    }
    return instantiate("fmi3InstantiateCoSimulation", instanceName, CoSimulation, instantiationToken, loggingOn,
                       instanceEnvironment, logMessage);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
                                               fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    UNUSED(instanceName); UNUSED(instantiationToken); UNUSED(resourcePath); UNUSED(visible); UNUSED(loggingOn);
    UNUSED(clockUpdate); UNUSED(lockPreemption); UNUSED(unlockPreemption);
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", MODEL_NAME " offers no Scheduled Execution");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
    fmu_free_instance(COMP);
    free(instance);
}

/* FMI 3.0 enters initialization mode and sets up the experiment in one call. */
fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Status status;
    UNUSED(toleranceDefined); UNUSED(tolerance); UNUSED(stopTimeDefined); UNUSED(stopTime);
    status = fmu_setup_experiment(COMP, "fmi3EnterInitializationMode", startTime);
    if (status != OK) return STATUS(status);
    return STATUS(fmu_enter_initialization_mode(COMP, "fmi3EnterInitializationMode"));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    return STATUS(fmu_exit_initialization_mode(COMP, "fmi3ExitInitializationMode"));
}
fmi3Status fmi3EnterEventMode(fmi3Instance instance) { return STATUS(fmu_enter_event_mode(COMP, "fmi3EnterEventMode")); }
fmi3Status fmi3Terminate(fmi3Instance instance) { return STATUS(fmu_terminate(COMP, "fmi3Terminate")); }
fmi3Status fmi3Reset(fmi3Instance instance) { return STATUS(fmu_reset(COMP, "fmi3Reset")); }

/* ------------------------------------------------------------------ variables */
/* Float64 adds what FMI 3.0 declares as variables: the independent variable time and the event indicators. */
fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[], size_t nValues) {
    size_t k;
#if N_EVENT_INDICATORS > 0
    double z[N_EVENT_INDICATORS];
    int have_z = 0;
#endif
    if (fmu_begin_get(COMP, "fmi3GetFloat64", vr, nvr, values, nValues) != OK) return fmi3Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] == VR3_TIME) {
            values[k] = COMP->time;
#if N_EVENT_INDICATORS > 0
        } else if (vr[k] >= VR3_INDICATORS && vr[k] < VR3_INDICATORS + N_EVENT_INDICATORS) {
            if (!have_z) { model_get_event_indicators(COMP, z); have_z = 1; }
            values[k] = z[vr[k] - VR3_INDICATORS];
#endif
        } else {
            long index = fmu_index(COMP, "fmi3GetFloat64", REALS, vr[k], VR3_REAL, 0);
            if (index < 0) return fmi3Error;
            values[k] = COMP->r[index];
        }
    }
    return fmi3OK;
}

/* The other types the model has: Int32 (= the model's Integer) and Boolean (an int 0 or 1 in the model). */
#define GETTER(Name, Type, array, Array, first, convert)                                                   \
    fmi3Status Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, Type values[],      \
                    size_t nValues) {                                                                     \
        size_t k;                                                                                         \
        if (fmu_begin_get(COMP, #Name, vr, nvr, values, nValues) != OK) return fmi3Error;                 \
        for (k = 0; k < nvr; k++) {                                                                       \
            long index = fmu_index(COMP, #Name, Array, vr[k], first, 0);                                  \
            if (index < 0) return fmi3Error;                                                              \
            values[k] = convert(COMP->array[index]);                                                      \
        }                                                                                                 \
        return fmi3OK;                                                                                    \
    }

#define SETTER(Name, Type, array, Array, first, convert)                                                   \
    fmi3Status Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const Type values[], \
                    size_t nValues) {                                                                     \
        size_t k;                                                                                         \
        if (fmu_begin_set(COMP, #Name, vr, nvr, values, nValues) != OK) return fmi3Error;                 \
        for (k = 0; k < nvr; k++) {                                                                       \
            long index = fmu_index(COMP, #Name, Array, vr[k], first, 1);                                  \
            if (index < 0) return fmi3Error;                                                              \
            if (fmu_check_value(COMP, #Name, Array, index, (double)values[k]) != OK) return fmi3Error;    \
            COMP->array[index] = convert(values[k]);                                                      \
        }                                                                                                 \
        return fmi3OK;                                                                                    \
    }

#define AS_IS(x) (x)
#define TO_BOOLEAN(x) ((x) != 0)
#define FROM_BOOLEAN(x) ((x) ? 1 : 0)
GETTER(fmi3GetInt32, fmi3Int32, i, INTEGERS, VR3_INTEGER, AS_IS)
GETTER(fmi3GetBoolean, fmi3Boolean, b, BOOLEANS, VR3_BOOLEAN, TO_BOOLEAN)
SETTER(fmi3SetFloat64, fmi3Float64, r, REALS, VR3_REAL, AS_IS)
SETTER(fmi3SetInt32, fmi3Int32, i, INTEGERS, VR3_INTEGER, AS_IS)
SETTER(fmi3SetBoolean, fmi3Boolean, b, BOOLEANS, VR3_BOOLEAN, FROM_BOOLEAN)

/* Types the model has no variables of: nothing to get or set (an empty call is fine). */
#define NO_VARIABLES(Name, Type)                                                                           \
    fmi3Status Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, Type values[],      \
                    size_t nValues) {                                                                     \
        UNUSED(vr); UNUSED(values); UNUSED(nValues);                                                      \
        return STATUS(fmu_no_variables(COMP, #Name, nvr));                                                \
    }

NO_VARIABLES(fmi3GetFloat32, fmi3Float32)
NO_VARIABLES(fmi3GetInt8, fmi3Int8)
NO_VARIABLES(fmi3GetUInt8, fmi3UInt8)
NO_VARIABLES(fmi3GetInt16, fmi3Int16)
NO_VARIABLES(fmi3GetUInt16, fmi3UInt16)
NO_VARIABLES(fmi3GetUInt32, fmi3UInt32)
NO_VARIABLES(fmi3GetInt64, fmi3Int64)
NO_VARIABLES(fmi3GetUInt64, fmi3UInt64)
NO_VARIABLES(fmi3GetString, fmi3String)
NO_VARIABLES(fmi3SetFloat32, const fmi3Float32)
NO_VARIABLES(fmi3SetInt8, const fmi3Int8)
NO_VARIABLES(fmi3SetUInt8, const fmi3UInt8)
NO_VARIABLES(fmi3SetInt16, const fmi3Int16)
NO_VARIABLES(fmi3SetUInt16, const fmi3UInt16)
NO_VARIABLES(fmi3SetUInt32, const fmi3UInt32)
NO_VARIABLES(fmi3SetInt64, const fmi3Int64)
NO_VARIABLES(fmi3SetUInt64, const fmi3UInt64)
NO_VARIABLES(fmi3SetString, const fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    UNUSED(vr); UNUSED(valueSizes); UNUSED(values); UNUSED(nValues);
    if (nvr == 0) return fmi3OK;
    NOT_SUPPORTED("fmi3GetBinary (no Binary variables)");
}
fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    UNUSED(vr); UNUSED(valueSizes); UNUSED(values); UNUSED(nValues);
    if (nvr == 0) return fmi3OK;
    NOT_SUPPORTED("fmi3SetBinary (no Binary variables)");
}
fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    UNUSED(vr); UNUSED(values);
    if (nvr == 0) return fmi3OK;
    NOT_SUPPORTED("fmi3GetClock (no clocks)");
}
fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    UNUSED(vr); UNUSED(values);
    if (nvr == 0) return fmi3OK;
    NOT_SUPPORTED("fmi3SetClock (no clocks)");
}

/* ------------------------------------------------------------------ unsupported optional features */
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference, size_t *nDependencies) {
    UNUSED(valueReference); UNUSED(nDependencies);
    NOT_SUPPORTED("fmi3GetNumberOfVariableDependencies");
}
fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent, size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[], size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[], size_t nDependencies) {
    UNUSED(dependent); UNUSED(elementIndicesOfDependent); UNUSED(independents); UNUSED(elementIndicesOfIndependents);
    UNUSED(dependencyKinds); UNUSED(nDependencies);
    NOT_SUPPORTED("fmi3GetVariableDependencies");
}
fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *s) { UNUSED(s); NOT_SUPPORTED("fmi3GetFMUState"); }
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState s) { UNUSED(s); NOT_SUPPORTED("fmi3SetFMUState"); }
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *s) { UNUSED(s); NOT_SUPPORTED("fmi3FreeFMUState"); }
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState s, size_t *size) {
    UNUSED(s); UNUSED(size);
    NOT_SUPPORTED("fmi3SerializedFMUStateSize");
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState s, fmi3Byte state[], size_t size) {
    UNUSED(s); UNUSED(state); UNUSED(size);
    NOT_SUPPORTED("fmi3SerializeFMUState");
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte state[], size_t size, fmi3FMUState *s) {
    UNUSED(state); UNUSED(size); UNUSED(s);
    NOT_SUPPORTED("fmi3DeserializeFMUState");
}
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    UNUSED(unknowns); UNUSED(nUnknowns); UNUSED(knowns); UNUSED(nKnowns); UNUSED(seed); UNUSED(nSeed);
    UNUSED(sensitivity); UNUSED(nSensitivity);
    NOT_SUPPORTED("fmi3GetDirectionalDerivative");
}
fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    UNUSED(unknowns); UNUSED(nUnknowns); UNUSED(knowns); UNUSED(nKnowns); UNUSED(seed); UNUSED(nSeed);
    UNUSED(sensitivity); UNUSED(nSensitivity);
    NOT_SUPPORTED("fmi3GetAdjointDerivative");
}
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) { NOT_SUPPORTED("fmi3EnterConfigurationMode (no structural parameters)"); }
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) { NOT_SUPPORTED("fmi3ExitConfigurationMode (no structural parameters)"); }
fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    UNUSED(vr); UNUSED(nvr); UNUSED(intervals); UNUSED(qualifiers);
    NOT_SUPPORTED("fmi3GetIntervalDecimal (no clocks)");
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) {
    UNUSED(vr); UNUSED(nvr); UNUSED(counters); UNUSED(resolutions); UNUSED(qualifiers);
    NOT_SUPPORTED("fmi3GetIntervalFraction (no clocks)");
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[]) {
    UNUSED(vr); UNUSED(nvr); UNUSED(shifts);
    NOT_SUPPORTED("fmi3GetShiftDecimal (no clocks)");
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
    UNUSED(vr); UNUSED(nvr); UNUSED(counters); UNUSED(resolutions);
    NOT_SUPPORTED("fmi3GetShiftFraction (no clocks)");
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 intervals[]) {
    UNUSED(vr); UNUSED(nvr); UNUSED(intervals);
    NOT_SUPPORTED("fmi3SetIntervalDecimal (no clocks)");
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    UNUSED(vr); UNUSED(nvr); UNUSED(counters); UNUSED(resolutions);
    NOT_SUPPORTED("fmi3SetIntervalFraction (no clocks)");
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 shifts[]) {
    UNUSED(vr); UNUSED(nvr); UNUSED(shifts);
    NOT_SUPPORTED("fmi3SetShiftDecimal (no clocks)");
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    UNUSED(vr); UNUSED(nvr); UNUSED(counters); UNUSED(resolutions);
    NOT_SUPPORTED("fmi3SetShiftFraction (no clocks)");
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference, fmi3Float64 activationTime) {
    UNUSED(clockReference); UNUSED(activationTime);
    NOT_SUPPORTED("fmi3ActivateModelPartition (no Scheduled Execution)");
}
fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
    UNUSED(vr); UNUSED(nvr); UNUSED(orders); UNUSED(values); UNUSED(nValues);
    NOT_SUPPORTED("fmi3GetOutputDerivatives");
}

/* ------------------------------------------------------------------ events (Model Exchange) */
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    if (!fmu_check_mode(COMP, "fmi3EvaluateDiscreteStates", MODE_BIT(MODE_EVENT) | MODE_BIT(MODE_CONTINUOUS) | MODE_BIT(MODE_STEP)))
        return fmi3Error;
    return fmi3OK;  /* no clocked partitions: nothing to evaluate */
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate, fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged, fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime) {
    int states_changed;
    double next;
    Status status = fmu_update_discrete_states(COMP, "fmi3UpdateDiscreteStates", &states_changed, &next);
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = states_changed ? fmi3True : fmi3False;
    if (nextEventTimeDefined) *nextEventTimeDefined = next >= 0 ? fmi3True : fmi3False;
    if (nextEventTime) *nextEventTime = next >= 0 ? next : 0;
    return STATUS(status);
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    return STATUS(fmu_enter_continuous_time_mode(COMP, "fmi3EnterContinuousTimeMode"));
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    if (enterEventMode) *enterEventMode = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    return STATUS(fmu_completed_integrator_step(COMP, "fmi3CompletedIntegratorStep"));
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) { return STATUS(fmu_set_time(COMP, "fmi3SetTime", time)); }

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 x[], size_t nx) {
    return STATUS(fmu_set_continuous_states(COMP, "fmi3SetContinuousStates", x, nx));
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[], size_t nx) {
    return STATUS(fmu_get_derivatives(COMP, "fmi3GetContinuousStateDerivatives", derivatives, nx));
}
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t ni) {
    return STATUS(fmu_get_event_indicators(COMP, "fmi3GetEventIndicators", eventIndicators, ni));
}
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 states[], size_t nx) {
    return STATUS(fmu_get_continuous_states(COMP, "fmi3GetContinuousStates", states, nx));
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nx) {
    return STATUS(fmu_get_nominals(COMP, "fmi3GetNominalsOfContinuousStates", nominals, nx));
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    if (!fmu_check_mode(COMP, "fmi3GetNumberOfEventIndicators", ANY_MODE) || !nEventIndicators) return fmi3Error;
    *nEventIndicators = N_EVENT_INDICATORS;
    return fmi3OK;
}
fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    if (!fmu_check_mode(COMP, "fmi3GetNumberOfContinuousStates", ANY_MODE) || !nContinuousStates) return fmi3Error;
    *nContinuousStates = N_STATES;
    return fmi3OK;
}

/* ------------------------------------------------------------------ Co-Simulation */
fmi3Status fmi3EnterStepMode(fmi3Instance instance) { return STATUS(fmu_enter_step_mode(COMP, "fmi3EnterStepMode")); }

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    Status status;
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    status = fmu_do_step(COMP, "fmi3DoStep", currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = status <= Warning ? COMP->time : currentCommunicationPoint;
    return STATUS(status);
}
