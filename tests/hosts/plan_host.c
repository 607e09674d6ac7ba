/* Runs the co-simulation master's step-plan runner (src/pendulab/cosim/c/plan_runner.c, as shipped in a
 * wheel) from a plain C host: linux64 natively, win64 under Wine. The host stands in for the FMUs: its
 * own get/set/step functions, called through the plan as fmpy's FMU functions are.
 *
 * usage: plan_host LIBRARY
 * prints: the runner's result and the logged rows of a 10-point plan, then the result, failing operation
 * and failing point of a plan whose step fails at t >= 0.5. */
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>

#include "library.h"

typedef struct {
    int32_t kind, pad;
    void *fn, *handle;
    const unsigned int *vrs;
    size_t n;
    char *base;
    ptrdiff_t row;
    char *target;
} Op;

typedef long (*run_fn)(const Op *, long, long, long, long, double, double, long *);

static double state = 1.0;
static int steps = 0;

static int get(void *h, const unsigned int *vrs, size_t n, void *out) {
    for (size_t i = 0; i < n; i++) ((double *)out)[i] = state + vrs[i];
    return 0;
}
static int set(void *h, const unsigned int *vrs, size_t n, void *in) {
    state += 0.25 * ((const double *)in)[0];
    return 0;
}
static int step(void *h, double t, double dt, int no_set_prior) {
    steps++;
    state = 0.5 * state + t + dt;
    return 0;
}
static int failing_step(void *h, double t, double dt, int no_set_prior) { return t >= 0.5 ? 3 /* fmi2Error */ : step(h, t, dt, 1); }

int main(int argc, char **argv) {
    if (argc != 2) { fprintf(stderr, "usage: plan_host LIBRARY\n"); return 2; }
    Library lib = open_library(argv[1]);
    if (!lib) { fprintf(stderr, "cannot load %s\n", argv[1]); return 1; }
    run_fn run = (run_fn)symbol(lib, "pendulab_run_plan");
    if (!run) { fprintf(stderr, "no pendulab_run_plan in %s\n", argv[1]); return 1; }

    enum { POINTS = 10 };
    static const unsigned int vrs[2] = {0, 1};
    double log[POINTS][2], input = 0.0;
    Op ops[5] = {
        {0, 0, (void *)get, NULL, vrs, 2, (char *)&log[0][0], sizeof log[0], NULL},   /* read outputs into row k */
        {1, 0, NULL, NULL, NULL, 0, (char *)&log[0][1], sizeof log[0], (char *)&input}, /* connection */
        {0, 0, (void *)set, NULL, vrs, 1, (char *)&input, 0, NULL},                     /* write the input */
        {3, 0, NULL, NULL, NULL, 0, NULL, 0, NULL},                                      /* barrier */
        {4, 0, (void *)step, NULL, NULL, 0, NULL, 0, NULL},                              /* doStep */
    };
    long failed_at = -2;
    long result = run(ops, 5, 0, POINTS, POINTS - 1, 0.0, 0.1, &failed_at);
    printf("%ld %d", result, steps);
    for (int k = 0; k < POINTS; k++) printf(" %.17g %.17g", log[k][0], log[k][1]);
    printf("\n");

    ops[4].fn = (void *)failing_step;
    state = 1.0;
    result = run(ops, 5, 0, POINTS, POINTS - 1, 0.0, 0.1, &failed_at);
    printf("%ld %ld %.17g\n", result, failed_at, state);
    return 0;
}
