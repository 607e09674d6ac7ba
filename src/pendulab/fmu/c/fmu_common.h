/* The FMI logic shared by fmi2_wrapper.c (FMI 2.0) and fmi3_wrapper.c (FMI 3.0), as the Modelica
 * Reference-FMUs' cosimulation.c serves both their fmi2Functions.c and fmi3Functions.c.
 *
 * fmu_common.c owns the instance's life cycle and its modes, the checks of every call (mode, pointers,
 * sizes, value references, fixed parameters), the continuous states, derivatives and event indicators, the
 * event update, the Co-Simulation step and the logging. A wrapper only translates: its API's types and
 * function names, its value references (FMI 3.0 numbers them across types), its callbacks and the results
 * that only its version has. Every function here takes the name of the FMI function it serves, for its
 * messages, and answers with the model's Status (in the order of fmi2Status and fmi3Status). */
#ifndef PENDULAB_FMU_COMMON_H
#define PENDULAB_FMU_COMMON_H

#include <stddef.h>

#include "fmu_model.h"

#define UNUSED(x) (void)(x)

/* The modes a function may be called in, as a bit set for fmu_check_mode. */
#define MODE_BIT(mode) (1 << (mode))
#define ANY_MODE (MODE_BIT(MODE_INSTANTIATED) | MODE_BIT(MODE_INITIALIZATION) | MODE_BIT(MODE_STEP) | \
                  MODE_BIT(MODE_EVENT) | MODE_BIT(MODE_CONTINUOUS) | MODE_BIT(MODE_TERMINATED))

/* ---- provided by each wrapper ---- */
/* Hand one formatted message to the importer's logger, if it gave one (fmu_log has filtered it). */
void fmu_log_message(Instance *comp, Status status, const char *category, const char *message);

/* ---- life cycle ---- */
/* Fill comp (zeroed, inside the wrapper's struct, its callbacks already set) for a new instance: checks the
 * GUID (FMI 3.0: instantiation token) and the interface type, copies the name, allocates the model's work
 * memory and sets the start values. On Error, comp holds nothing to free. */
Status fmu_instantiate(Instance *comp, const char *function, const char *instance_name, const char *guid,
                       InterfaceType type, int logging_on);
/* Free what fmu_instantiate allocated (not comp itself, which the wrapper allocated). */
void fmu_free_instance(Instance *comp);
Status fmu_set_debug_logging(Instance *comp, int logging_on);
/* Whether comp may be called in its current mode (a bit set of MODE_BIT); logs the refusal. */
int fmu_check_mode(Instance *comp, const char *function, int allowed);
Status fmu_setup_experiment(Instance *comp, const char *function, double start_time);
Status fmu_enter_initialization_mode(Instance *comp, const char *function);
Status fmu_exit_initialization_mode(Instance *comp, const char *function);
Status fmu_enter_event_mode(Instance *comp, const char *function);
Status fmu_enter_continuous_time_mode(Instance *comp, const char *function);
Status fmu_enter_step_mode(Instance *comp, const char *function);
Status fmu_terminate(Instance *comp, const char *function);
Status fmu_reset(Instance *comp, const char *function);

/* ---- variables: one array per base type of the Instance ---- */
typedef enum { REALS, INTEGERS, BOOLEANS } VariableArray;
/* Before a getter's loop over nvr value references: mode and pointer checks, n_values == nvr (FMI 3.0's
 * array sizes; every variable is a scalar), then the outputs brought up to date. */
Status fmu_begin_get(Instance *comp, const char *function, const void *vr, size_t nvr, const void *values,
                     size_t n_values);
/* Before a setter's loop: the same checks; the outputs are stale from here on. */
Status fmu_begin_set(Instance *comp, const char *function, const void *vr, size_t nvr, const void *values,
                     size_t n_values);
/* The index in comp's array of the variable whose value reference is vr (numbered from first in that
 * array), or -1 (logged) if there is none, or if it is set (to_set) as a fixed parameter after initialization. */
long fmu_index(Instance *comp, const char *function, VariableArray array, unsigned vr, unsigned first, int to_set);
/* Whether value lies within the range (min/max) of the variable at index of array; logs the refusal naming the
 * variable, the value and the range. A setter calls it before it stores the value. */
Status fmu_check_value(Instance *comp, const char *function, VariableArray array, long index, double value);
/* Getters and setters of types the model has no variables of: an empty call is fine, anything else an error. */
Status fmu_no_variables(Instance *comp, const char *function, size_t nvr);
Status fmu_not_supported(Instance *comp, const char *what);

/* ---- Model Exchange ---- */
Status fmu_set_time(Instance *comp, const char *function, double time);
Status fmu_completed_integrator_step(Instance *comp, const char *function);
Status fmu_get_continuous_states(Instance *comp, const char *function, double x[], size_t nx);
Status fmu_set_continuous_states(Instance *comp, const char *function, const double x[], size_t nx);
Status fmu_get_derivatives(Instance *comp, const char *function, double dx[], size_t nx);
Status fmu_get_event_indicators(Instance *comp, const char *function, double z[], size_t nz);
Status fmu_get_nominals(Instance *comp, const char *function, double nominals[], size_t nx);
/* Event mode: the model's discrete update (it iterates to a fixed point itself: one call is enough).
 * *states_changed: whether it reset the continuous states; *next_event_time: the next time event, or a
 * negative number if none. Both are set (to 0 and -1) even if the call fails. */
Status fmu_update_discrete_states(Instance *comp, const char *function, int *states_changed, double *next_event_time);

/* ---- Co-Simulation ---- */
/* One communication step from t to t + h: the model resolves its switches inside the step (no event mode). */
Status fmu_do_step(Instance *comp, const char *function, double t, double h);

#endif
