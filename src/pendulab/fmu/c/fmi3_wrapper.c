/* The FMI 3.0 wrapper (Model Exchange and Co-Simulation) around the same model code as fmi2_wrapper.c.
 *
 * As in the Modelica Reference-FMUs, one model (model.c, through fmu_model.h) serves both FMI versions;
 * this file owns what FMI 3.0 does differently: the instantiate functions, value references unique across
 * types (Float64, Int32, Boolean, then time and the event indicators: see variables.h, VR3_...), the
 * array-aware getters and setters, fmi3UpdateDiscreteStates and fmi3DoStep's extra results.
 * Scheduled Execution, clocks, FMU states and directional derivatives are not offered (the
 * modelDescription.xml says so) and answer with an error. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "fmu_model.h"

#define UNUSED(x) (void)(x)

/* The model's instance, then what only this wrapper needs. */
typedef struct {
    Instance model;
    fmi3InstanceEnvironment environment;
    fmi3LogMessageCallback logger;
} Component;

void fmu_log(Instance *comp, Status status, const char *category, const char *message, ...) {
    char buffer[1024];
    va_list args;
    Component *component = (Component *)comp;
    if (!component || !component->logger) return;
    if (!comp->logging_on && status == OK) return;
    va_start(args, message);
    vsnprintf(buffer, sizeof(buffer), message, args);
    va_end(args);
    component->logger(component->environment, (fmi3Status)status, category, buffer);
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
    do { if (!in_mode(comp, function, allowed)) return fmi3Error; } while (0)
#define NOT_SUPPORTED(what)                                                                                \
    do {                                                                                                  \
        fmu_log((Instance *)instance, Error, "logStatusError", what " is not supported by this FMU");     \
        return fmi3Error;                                                                                 \
    } while (0)

/* ------------------------------------------------------------------ inquire and log */
const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories, const fmi3String categories[]) {
    Instance *comp = (Instance *)instance;
    UNUSED(nCategories); UNUSED(categories);
    if (!comp) return fmi3Error;
    comp->logging_on = loggingOn ? 1 : 0;
    return fmi3OK;
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

static fmi3Instance instantiate(fmi3String instanceName, InterfaceType type, fmi3String instantiationToken,
                                fmi3Boolean loggingOn, fmi3InstanceEnvironment environment, fmi3LogMessageCallback logger) {
    Component *component;
    Instance *comp;
    if (!instanceName || !instantiationToken) return NULL;
    if (strcmp(instantiationToken, MODEL_GUID) != 0) {
        if (logger)
            logger(environment, fmi3Error, "logStatusError",
                   "wrong instantiationToken: the modelDescription.xml does not belong to this binary (expected " MODEL_GUID ")");
        return NULL;
    }
#if N_STATES == 0
    if (type == ModelExchange) {
        if (logger) logger(environment, fmi3Error, "logStatusError", MODEL_NAME " supports Co-Simulation only");
        return NULL;
    }
#endif
    component = (Component *)calloc(1, sizeof(Component));
    if (!component) return NULL;
    comp = &component->model;
    comp->instance_name = (const char *)malloc(strlen(instanceName) + 1);
    if (!comp->instance_name) { free(component); return NULL; }
    strcpy((char *)comp->instance_name, instanceName);
    component->environment = environment;
    component->logger = logger;
    comp->type = type;
    comp->logging_on = loggingOn ? 1 : 0;
    comp->work = model_work_size() ? calloc(1, model_work_size()) : NULL;
    if (model_work_size() && !comp->work) {
        free((void *)comp->instance_name);
        free(component);
        return NULL;
    }
    comp->mode = MODE_INSTANTIATED;
    set_start_values(comp);
    return component;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
                                          fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    UNUSED(resourcePath); UNUSED(visible);
    return instantiate(instanceName, ModelExchange, instantiationToken, loggingOn, instanceEnvironment, logMessage);
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
    return instantiate(instanceName, CoSimulation, instantiationToken, loggingOn, instanceEnvironment, logMessage);
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
    Instance *comp = (Instance *)instance;
    if (!comp) return;
    free(comp->work);
    free((void *)comp->instance_name);
    free((Component *)comp);
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Instance *comp = (Instance *)instance;
    UNUSED(toleranceDefined); UNUSED(tolerance); UNUSED(stopTimeDefined); UNUSED(stopTime);
    CHECK("fmi3EnterInitializationMode", M(MODE_INSTANTIATED));
    comp->time = startTime;
    comp->mode = MODE_INITIALIZATION;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    Instance *comp = (Instance *)instance;
    Status status;
    CHECK("fmi3ExitInitializationMode", M(MODE_INITIALIZATION));
    status = model_initialize(comp);
    if (status > Warning) return (fmi3Status)status;
    comp->outputs_stale = 1;
    /* Model Exchange continues in event mode; Co-Simulation without event mode in step mode. */
    comp->mode = comp->type == CoSimulation ? MODE_STEP : MODE_EVENT;
    return (fmi3Status)status;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3EnterEventMode", M(MODE_EVENT) | M(MODE_CONTINUOUS));
    comp->mode = MODE_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3Terminate", M(MODE_STEP) | M(MODE_EVENT) | M(MODE_CONTINUOUS));
    comp->mode = MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3Reset", ANY_MODE);
    comp->time = 0;
    comp->mode = MODE_INSTANTIATED;
    if (comp->work) memset(comp->work, 0, model_work_size());
    set_start_values(comp);
    return fmi3OK;
}

/* ------------------------------------------------------------------ variables */
static void refresh(Instance *comp) {
    if (comp->outputs_stale) {
        model_update_outputs(comp);
        comp->outputs_stale = 0;
    }
}

static int check_sizes(Instance *comp, const char *function, const void *vr, size_t nvr, const void *values, size_t nValues) {
    if (nvr > 0 && (!vr || !values)) return 0;
    if (nValues != nvr) {  /* every variable is a scalar */
        fmu_log(comp, Error, "logStatusError", "%s: %u values for %u scalar variables", function, (unsigned)nValues, (unsigned)nvr);
        return 0;
    }
    return 1;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[], size_t nValues) {
    Instance *comp = (Instance *)instance;
    size_t k;
#if N_EVENT_INDICATORS > 0
    double z[N_EVENT_INDICATORS];
    int have_z = 0;
#endif
    CHECK("fmi3GetFloat64", ANY_MODE);
    if (!check_sizes(comp, "fmi3GetFloat64", vr, nvr, values, nValues)) return fmi3Error;
    if (comp->mode != MODE_INSTANTIATED) refresh(comp);
    for (k = 0; k < nvr; k++) {
        if (vr[k] < VR3_REAL + N_REALS) {
            values[k] = comp->r[vr[k] - VR3_REAL];
        } else if (vr[k] == VR3_TIME) {
            values[k] = comp->time;
#if N_EVENT_INDICATORS > 0
        } else if (vr[k] >= VR3_INDICATORS && vr[k] < VR3_INDICATORS + N_EVENT_INDICATORS) {
            if (!have_z) { model_get_event_indicators(comp, z); have_z = 1; }
            values[k] = z[vr[k] - VR3_INDICATORS];
#endif
        } else {
            fmu_log(comp, Error, "logStatusError", "fmi3GetFloat64: %u is not the value reference of a Float64 variable", vr[k]);
            return fmi3Error;
        }
    }
    return fmi3OK;
}

static int in_range(fmi3ValueReference vr, unsigned first, unsigned count) { return vr >= first && vr - first < count; }

/* The variables the importer may set: Float64 (= the model's Real), Int32 (Integer), Boolean.
 * Fixed parameters only before the end of initialization (as fmi2_wrapper.c). */
#define SETTER(Name, Type, array, first, count, fixed, convert)                                             \
    fmi3Status Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const Type values[], \
                    size_t nValues) {                                                                     \
        Instance *comp = (Instance *)instance;                                                            \
        size_t k;                                                                                         \
        int initialized;                                                                                  \
        CHECK(#Name, M(MODE_INSTANTIATED) | M(MODE_INITIALIZATION) | M(MODE_STEP) | M(MODE_EVENT) |      \
                         M(MODE_CONTINUOUS));                                                             \
        if (!check_sizes(comp, #Name, vr, nvr, values, nValues)) return fmi3Error;                        \
        initialized = comp->mode != MODE_INSTANTIATED && comp->mode != MODE_INITIALIZATION;               \
        for (k = 0; k < nvr; k++) {                                                                       \
            if (!in_range(vr[k], (first), (count))) {                                                     \
                fmu_log(comp, Error, "logStatusError", #Name ": %u is not the value reference of a "      \
                        "variable of this type that can be set", vr[k]);                                  \
                return fmi3Error;                                                                         \
            }                                                                                             \
            if (initialized && fixed[vr[k] - (first)]) {                                                  \
                fmu_log(comp, Error, "logStatusError",                                                   \
                        #Name ": value reference %u is a fixed parameter; set it before initialization",  \
                        vr[k]);                                                                           \
                return fmi3Error;                                                                         \
            }                                                                                             \
            comp->array[vr[k] - (first)] = convert(values[k]);                                            \
        }                                                                                                 \
        comp->outputs_stale = 1;                                                                          \
        return fmi3OK;                                                                                    \
    }

#define AS_IS(x) (x)
#define AS_INT_BOOLEAN(x) ((x) ? 1 : 0)
SETTER(fmi3SetFloat64, fmi3Float64, r, VR3_REAL, N_REALS, REAL_FIXED, AS_IS)
SETTER(fmi3SetInt32, fmi3Int32, i, VR3_INTEGER, N_INTEGERS, INTEGER_FIXED, AS_IS)
SETTER(fmi3SetBoolean, fmi3Boolean, b, VR3_BOOLEAN, N_BOOLEANS, BOOLEAN_FIXED, AS_INT_BOOLEAN)

#define GETTER(Name, Type, array, first, count, convert)                                                   \
    fmi3Status Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, Type values[],      \
                    size_t nValues) {                                                                     \
        Instance *comp = (Instance *)instance;                                                            \
        size_t k;                                                                                         \
        CHECK(#Name, ANY_MODE);                                                                           \
        if (!check_sizes(comp, #Name, vr, nvr, values, nValues)) return fmi3Error;                        \
        if (comp->mode != MODE_INSTANTIATED) refresh(comp);                                               \
        for (k = 0; k < nvr; k++) {                                                                       \
            if (!in_range(vr[k], (first), (count))) {                                                     \
                fmu_log(comp, Error, "logStatusError", #Name ": %u is not the value reference of a "      \
                        "variable of this type", vr[k]);                                                  \
                return fmi3Error;                                                                         \
            }                                                                                             \
            values[k] = convert(comp->array[vr[k] - (first)]);                                            \
        }                                                                                                 \
        return fmi3OK;                                                                                    \
    }

#define AS_BOOLEAN(x) ((x) != 0)
GETTER(fmi3GetInt32, fmi3Int32, i, VR3_INTEGER, N_INTEGERS, AS_IS)
GETTER(fmi3GetBoolean, fmi3Boolean, b, VR3_BOOLEAN, N_BOOLEANS, AS_BOOLEAN)

/* Types the model has no variables of: nothing to get or set (an empty call is fine). */
#define NO_VARIABLES(Name, Type)                                                                           \
    fmi3Status Name(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, Type values[],      \
                    size_t nValues) {                                                                     \
        UNUSED(vr); UNUSED(values); UNUSED(nValues);                                                      \
        if (nvr == 0) return fmi3OK;                                                                      \
        fmu_log((Instance *)instance, Error, "logStatusError", #Name ": this model has no such variables"); \
        return fmi3Error;                                                                                 \
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
    Instance *comp = (Instance *)instance;
    CHECK("fmi3EvaluateDiscreteStates", M(MODE_EVENT) | M(MODE_CONTINUOUS) | M(MODE_STEP));
    return fmi3OK;  /* no clocked partitions: nothing to evaluate */
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate, fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged, fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined, fmi3Float64 *nextEventTime) {
    Instance *comp = (Instance *)instance;
    int states_changed = 0;
    double next = -1;
    CHECK("fmi3UpdateDiscreteStates", M(MODE_EVENT));
#if N_EVENT_INDICATORS > 0
    {
        Status status = model_event_update(comp, &states_changed);
        if (status > Warning) return (fmi3Status)status;
    }
#endif
#if N_STATES > 0
    next = model_next_time_event(comp);
#endif
    /* The model iterates its discrete update to a fixed point itself: one call is enough. */
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = states_changed ? fmi3True : fmi3False;
    if (nextEventTimeDefined) *nextEventTimeDefined = next >= 0 ? fmi3True : fmi3False;
    if (nextEventTime) *nextEventTime = next >= 0 ? next : 0;
    comp->outputs_stale = 1;
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3EnterContinuousTimeMode", M(MODE_EVENT));
    if (comp->type != ModelExchange) {
        fmu_log(comp, Error, "logStatusError", "fmi3EnterContinuousTimeMode: only for Model Exchange");
        return fmi3Error;
    }
    comp->mode = MODE_CONTINUOUS;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    Instance *comp = (Instance *)instance;
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    CHECK("fmi3CompletedIntegratorStep", M(MODE_CONTINUOUS));
    if (enterEventMode) *enterEventMode = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3SetTime", M(MODE_EVENT) | M(MODE_CONTINUOUS));
    comp->time = time;
    comp->outputs_stale = 1;
    return fmi3OK;
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 x[], size_t nx) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3SetContinuousStates", M(MODE_CONTINUOUS));
#if N_STATES > 0
    if (nx != N_STATES || !x) return fmi3Error;
    model_set_states(comp, x);
    comp->outputs_stale = 1;
    return fmi3OK;
#else
    UNUSED(x); UNUSED(nx);
    return fmi3Error;
#endif
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[], size_t nx) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3GetContinuousStateDerivatives", M(MODE_INITIALIZATION) | M(MODE_EVENT) | M(MODE_CONTINUOUS) | M(MODE_TERMINATED));
#if N_STATES > 0
    if (nx != N_STATES || !derivatives) return fmi3Error;
    model_get_derivatives(comp, derivatives);
    return fmi3OK;
#else
    UNUSED(derivatives); UNUSED(nx);
    return fmi3Error;
#endif
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t ni) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3GetEventIndicators", M(MODE_INITIALIZATION) | M(MODE_EVENT) | M(MODE_CONTINUOUS) | M(MODE_TERMINATED));
    if (ni != N_EVENT_INDICATORS) {
        fmu_log(comp, Error, "logStatusError", "fmi3GetEventIndicators: %u indicators asked, the model has %d",
                (unsigned)ni, N_EVENT_INDICATORS);
        return fmi3Error;
    }
#if N_EVENT_INDICATORS > 0
    model_get_event_indicators(comp, eventIndicators);
#else
    UNUSED(eventIndicators);
#endif
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 states[], size_t nx) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3GetContinuousStates", M(MODE_INITIALIZATION) | M(MODE_EVENT) | M(MODE_CONTINUOUS) | M(MODE_TERMINATED));
#if N_STATES > 0
    if (nx != N_STATES || !states) return fmi3Error;
    model_get_states(comp, states);
    return fmi3OK;
#else
    UNUSED(states); UNUSED(nx);
    return fmi3Error;
#endif
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nx) {
    Instance *comp = (Instance *)instance;
    size_t k;
    CHECK("fmi3GetNominalsOfContinuousStates", ANY_MODE);
    if (nx != N_STATES || (nx > 0 && !nominals)) return fmi3Error;
    for (k = 0; k < nx; k++) nominals[k] = 1.0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3GetNumberOfEventIndicators", ANY_MODE);
    if (!nEventIndicators) return fmi3Error;
    *nEventIndicators = N_EVENT_INDICATORS;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3GetNumberOfContinuousStates", ANY_MODE);
    if (!nContinuousStates) return fmi3Error;
    *nContinuousStates = N_STATES;
    return fmi3OK;
}

/* ------------------------------------------------------------------ Co-Simulation */
fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    Instance *comp = (Instance *)instance;
    CHECK("fmi3EnterStepMode", M(MODE_EVENT));
    if (comp->type != CoSimulation) {
        fmu_log(comp, Error, "logStatusError", "fmi3EnterStepMode: only for Co-Simulation");
        return fmi3Error;
    }
    comp->mode = MODE_STEP;
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    Instance *comp = (Instance *)instance;
    Status status;
    UNUSED(noSetFMUStatePriorToCurrentPoint);
    CHECK("fmi3DoStep", M(MODE_STEP));
    if (communicationStepSize <= 0) {
        fmu_log(comp, Error, "logStatusError", "fmi3DoStep: step size %g must be positive", communicationStepSize);
        return fmi3Error;
    }
    /* The same step as FMI 2.0: the model resolves its switches inside the step (no event mode). */
    status = model_do_step(comp, currentCommunicationPoint, communicationStepSize);
    comp->time = currentCommunicationPoint + communicationStepSize;
    comp->outputs_stale = 1;
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = status <= Warning ? comp->time : currentCommunicationPoint;
    return (fmi3Status)status;
}
