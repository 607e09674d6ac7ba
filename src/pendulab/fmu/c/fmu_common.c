/* The FMI logic of every pendulab FMU, whatever its FMI version: see fmu_common.h. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_common.h"

/* ------------------------------------------------------------------ logging */
void fmu_log(Instance *comp, Status status, const char *category, const char *message, ...) {
    char buffer[1024];
    va_list args;
    if (!comp || (!comp->logging_on && status == OK)) return;
    va_start(args, message);
    vsnprintf(buffer, sizeof(buffer), message, args);
    va_end(args);
    fmu_log_message(comp, status, category, buffer);
}

Status fmu_not_supported(Instance *comp, const char *what) {
    fmu_log(comp, Error, "logStatusError", "%s is not supported by this FMU", what);
    return Error;
}

/* ------------------------------------------------------------------ life cycle and modes */
int fmu_check_mode(Instance *comp, const char *function, int allowed) {
    if (!comp) return 0;
    if (allowed & MODE_BIT(comp->mode)) return 1;
    fmu_log(comp, Error, "logStatusError", "%s must not be called in the current state (mode %d)", function, (int)comp->mode);
    return 0;
}

#define CHECK(function, allowed) \
    do { if (!fmu_check_mode(comp, function, allowed)) return Error; } while (0)

static void set_start_values(Instance *comp) {
    int k;
    for (k = 0; k < N_REALS; k++) comp->r[k] = REAL_START[k];
    for (k = 0; k < N_INTEGERS; k++) comp->i[k] = INTEGER_START[k];
    for (k = 0; k < N_BOOLEANS; k++) comp->b[k] = BOOLEAN_START[k];
    model_reset(comp);
    comp->outputs_stale = 1;
}

Status fmu_instantiate(Instance *comp, const char *function, const char *instance_name, const char *guid,
                       InterfaceType type, int logging_on) {
    char *name;
    /* The caller's name until it is copied, for the messages below. */
    comp->instance_name = instance_name;
    comp->type = type;
    comp->logging_on = logging_on ? 1 : 0;
    if (strcmp(guid, MODEL_GUID) != 0) {
        fmu_log(comp, Error, "logStatusError",
                "%s: wrong GUID (instantiation token) %s, expected %s: the modelDescription.xml does not belong to this binary",
                function, guid, MODEL_GUID);
        return Error;
    }
#if N_STATES == 0
    if (type == ModelExchange) {
        fmu_log(comp, Error, "logStatusError", "%s: %s supports Co-Simulation only", function, MODEL_NAME);
        return Error;
    }
#endif
    name = (char *)malloc(strlen(instance_name) + 1);
    if (!name) return Error;
    strcpy(name, instance_name);
    comp->work = model_work_size() ? calloc(1, model_work_size()) : NULL;
    if (model_work_size() && !comp->work) {
        free(name);
        return Error;
    }
    comp->instance_name = name;
    comp->mode = MODE_INSTANTIATED;
    set_start_values(comp);
    return OK;
}

void fmu_free_instance(Instance *comp) {
    if (!comp) return;
    free(comp->work);
    free((void *)comp->instance_name);
}

Status fmu_set_debug_logging(Instance *comp, int logging_on) {
    if (!comp) return Error;
    comp->logging_on = logging_on ? 1 : 0;
    return OK;
}

Status fmu_setup_experiment(Instance *comp, const char *function, double start_time) {
    CHECK(function, MODE_BIT(MODE_INSTANTIATED));
    comp->time = start_time;
    return OK;
}

Status fmu_enter_initialization_mode(Instance *comp, const char *function) {
    CHECK(function, MODE_BIT(MODE_INSTANTIATED));
    comp->mode = MODE_INITIALIZATION;
    return OK;
}

Status fmu_exit_initialization_mode(Instance *comp, const char *function) {
    Status status;
    char message[512];
    CHECK(function, MODE_BIT(MODE_INITIALIZATION));
    /* The conditions between variables (each variable's own range was checked when it was set). */
    if (!check_constraints(comp->r, comp->i, comp->b, message, sizeof(message))) {
        fmu_log(comp, Error, "logStatusError", "%s: %s", function, message);
        return Error;
    }
    status = model_initialize(comp);
    if (status > Warning) return status;
    comp->outputs_stale = 1;
    /* Model Exchange continues in event mode; Co-Simulation (FMI 3.0: without event mode) in step mode. */
    comp->mode = comp->type == CoSimulation ? MODE_STEP : MODE_EVENT;
    return status;
}

Status fmu_enter_event_mode(Instance *comp, const char *function) {
    CHECK(function, MODE_BIT(MODE_EVENT) | MODE_BIT(MODE_CONTINUOUS));
    comp->mode = MODE_EVENT;
    return OK;
}

/* From event mode to the mode of the instance's interface type (which must be type). */
static Status leave_event_mode(Instance *comp, const char *function, InterfaceType type, Mode mode) {
    CHECK(function, MODE_BIT(MODE_EVENT));
    if (comp->type != type) {
        fmu_log(comp, Error, "logStatusError", "%s: only for %s", function,
                type == ModelExchange ? "Model Exchange" : "Co-Simulation");
        return Error;
    }
    comp->mode = mode;
    return OK;
}

Status fmu_enter_continuous_time_mode(Instance *comp, const char *function) {
    return leave_event_mode(comp, function, ModelExchange, MODE_CONTINUOUS);
}

Status fmu_enter_step_mode(Instance *comp, const char *function) {
    return leave_event_mode(comp, function, CoSimulation, MODE_STEP);
}

Status fmu_terminate(Instance *comp, const char *function) {
    CHECK(function, MODE_BIT(MODE_STEP) | MODE_BIT(MODE_EVENT) | MODE_BIT(MODE_CONTINUOUS));
    comp->mode = MODE_TERMINATED;
    return OK;
}

Status fmu_reset(Instance *comp, const char *function) {
    CHECK(function, ANY_MODE);
    comp->time = 0;
    comp->mode = MODE_INSTANTIATED;
    if (comp->work) memset(comp->work, 0, model_work_size());
    set_start_values(comp);
    return OK;
}

/* ------------------------------------------------------------------ variables */
static Status check_arguments(Instance *comp, const char *function, const void *vr, size_t nvr, const void *values,
                              size_t n_values) {
    if (nvr > 0 && (!vr || !values)) return Error;
    if (n_values != nvr) {
        fmu_log(comp, Error, "logStatusError", "%s: %u values for %u scalar variables", function, (unsigned)n_values, (unsigned)nvr);
        return Error;
    }
    return OK;
}

Status fmu_begin_get(Instance *comp, const char *function, const void *vr, size_t nvr, const void *values,
                     size_t n_values) {
    CHECK(function, ANY_MODE);
    if (check_arguments(comp, function, vr, nvr, values, n_values) != OK) return Error;
    if (comp->mode != MODE_INSTANTIATED && comp->outputs_stale) {
        model_update_outputs(comp);
        comp->outputs_stale = 0;
    }
    return OK;
}

Status fmu_begin_set(Instance *comp, const char *function, const void *vr, size_t nvr, const void *values,
                     size_t n_values) {
    CHECK(function, MODE_BIT(MODE_INSTANTIATED) | MODE_BIT(MODE_INITIALIZATION) | MODE_BIT(MODE_STEP) |
                    MODE_BIT(MODE_EVENT) | MODE_BIT(MODE_CONTINUOUS));
    if (check_arguments(comp, function, vr, nvr, values, n_values) != OK) return Error;
    comp->outputs_stale = 1;
    return OK;
}

long fmu_index(Instance *comp, const char *function, VariableArray array, unsigned vr, unsigned first, int to_set) {
    static const unsigned count[] = {N_REALS, N_INTEGERS, N_BOOLEANS};
    static const unsigned char *const fixed[] = {REAL_FIXED, INTEGER_FIXED, BOOLEAN_FIXED};
    unsigned index = vr - first;
    if (vr < first || index >= count[array]) {
        fmu_log(comp, Error, "logStatusError", "%s: %u is not the value reference of a variable of this type", function, vr);
        return -1;
    }
    /* Fixed parameters only before the end of initialization. */
    if (to_set && fixed[array][index] && comp->mode != MODE_INSTANTIATED && comp->mode != MODE_INITIALIZATION) {
        fmu_log(comp, Error, "logStatusError", "%s: value reference %u is a fixed parameter; set it before initialization",
                function, vr);
        return -1;
    }
    return (long)index;
}

Status fmu_check_value(Instance *comp, const char *function, VariableArray array, long index, double value) {
    static const VariableInfo *const info[] = {REAL_INFO, INTEGER_INFO, BOOLEAN_INFO};
    const VariableInfo *v = &info[array][index];
    /* Written so that NaN fails too; a variable without a range (words NULL) takes any value. */
    if (!v->words || (value >= v->min && value <= v->max)) return OK;
    fmu_log(comp, Error, "logStatusError", "%s: %s = %g is outside its range %s; the value was not set", function,
            v->name, value, v->words);
    return Error;
}

Status fmu_no_variables(Instance *comp, const char *function, size_t nvr) {
    if (nvr == 0) return OK;
    fmu_log(comp, Error, "logStatusError", "%s: this model has no such variables", function);
    return Error;
}

/* ------------------------------------------------------------------ Model Exchange */
#define ME_QUERY_MODES (MODE_BIT(MODE_INITIALIZATION) | MODE_BIT(MODE_EVENT) | MODE_BIT(MODE_CONTINUOUS) | MODE_BIT(MODE_TERMINATED))

/* A vector of the continuous states' size (or the event indicators'): n elements at a non-null address. */
static Status check_vector(Instance *comp, const char *function, const void *vector, size_t n, size_t expected) {
    if (n != expected) {
        fmu_log(comp, Error, "logStatusError", "%s: %u elements given, the model has %u", function, (unsigned)n, (unsigned)expected);
        return Error;
    }
    return n > 0 && !vector ? Error : OK;
}

Status fmu_set_time(Instance *comp, const char *function, double time) {
    CHECK(function, MODE_BIT(MODE_EVENT) | MODE_BIT(MODE_CONTINUOUS));
    comp->time = time;
    comp->outputs_stale = 1;
    return OK;
}

Status fmu_completed_integrator_step(Instance *comp, const char *function) {
    CHECK(function, MODE_BIT(MODE_CONTINUOUS));
    return OK;
}

Status fmu_get_continuous_states(Instance *comp, const char *function, double x[], size_t nx) {
    CHECK(function, ME_QUERY_MODES);
    if (check_vector(comp, function, x, nx, N_STATES) != OK) return Error;
#if N_STATES > 0
    model_get_states(comp, x);
    return OK;
#else
    return Error;  /* a Co-Simulation-only model has no Model Exchange instances */
#endif
}

Status fmu_set_continuous_states(Instance *comp, const char *function, const double x[], size_t nx) {
    CHECK(function, MODE_BIT(MODE_CONTINUOUS));
    if (check_vector(comp, function, x, nx, N_STATES) != OK) return Error;
#if N_STATES > 0
    model_set_states(comp, x);
    comp->outputs_stale = 1;
    return OK;
#else
    return Error;
#endif
}

Status fmu_get_derivatives(Instance *comp, const char *function, double dx[], size_t nx) {
    CHECK(function, ME_QUERY_MODES);
    if (check_vector(comp, function, dx, nx, N_STATES) != OK) return Error;
#if N_STATES > 0
    model_get_derivatives(comp, dx);
    return OK;
#else
    return Error;
#endif
}

Status fmu_get_event_indicators(Instance *comp, const char *function, double z[], size_t nz) {
    CHECK(function, ME_QUERY_MODES);
    if (check_vector(comp, function, z, nz, N_EVENT_INDICATORS) != OK) return Error;
#if N_EVENT_INDICATORS > 0
    model_get_event_indicators(comp, z);
#endif
    return OK;
}

Status fmu_get_nominals(Instance *comp, const char *function, double nominals[], size_t nx) {
    size_t k;
    CHECK(function, ANY_MODE);
    if (check_vector(comp, function, nominals, nx, N_STATES) != OK) return Error;
    for (k = 0; k < nx; k++) nominals[k] = 1.0;
    return OK;
}

Status fmu_update_discrete_states(Instance *comp, const char *function, int *states_changed, double *next_event_time) {
    *states_changed = 0;
    *next_event_time = -1;
    CHECK(function, MODE_BIT(MODE_EVENT));
#if N_EVENT_INDICATORS > 0
    {
        Status status = model_event_update(comp, states_changed);
        if (status > Warning) return status;
    }
#endif
#if N_STATES > 0
    *next_event_time = model_next_time_event(comp);
#endif
    comp->outputs_stale = 1;
    return OK;
}

/* ------------------------------------------------------------------ Co-Simulation */
Status fmu_do_step(Instance *comp, const char *function, double t, double h) {
    Status status;
    CHECK(function, MODE_BIT(MODE_STEP));
    if (h <= 0) {
        fmu_log(comp, Error, "logStatusError", "%s: step size %g must be positive", function, h);
        return Error;
    }
    status = model_do_step(comp, t, h);
    comp->time = t + h;
    comp->outputs_stale = 1;
    return status;
}
