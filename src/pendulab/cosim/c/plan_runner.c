/* Native runner for the master's step plan (pendulab.cosim.master._Plan).
 *
 * The plan is a flat list of operations on fixed addresses, built and owned by Python: FMI get/set
 * calls, value copies along connections, and the FMUs' fmi2DoStep. Running it here instead of in a
 * Python loop removes the interpreter from the 1 kHz loop; the FMUs are the same instances fmpy loaded. */
#include <stddef.h>
#include <stdint.h>

typedef int (*access_fn)(void *, const unsigned int *, size_t, void *);
typedef int (*step_fn)(void *, double, double, int);

enum { OP_ACCESS = 0, OP_COPY_F64 = 1, OP_COPY_I32 = 2, OP_BARRIER = 3, OP_STEP = 4 };

typedef struct {
    int32_t kind;
    int32_t pad;
    void *fn;               /* OP_ACCESS, OP_STEP */
    void *handle;           /* fmi2Component */
    const unsigned int *vrs;
    size_t n;
    char *base;             /* data address at k = 0 (ACCESS, source of COPY) */
    ptrdiff_t row;          /* bytes per communication point (0: a fixed buffer) */
    char *target;           /* COPY: destination */
} Op;

/* Runs communication points k0 .. k1-1. At k == last the plan stops at the barrier (no step after
 * the final point). Returns -1 when done, else the index of the operation that failed, with the
 * communication point it failed at in *failed_at. */
long pendulab_run_plan(const Op *ops, long n_ops, long k0, long k1, long last, double t0, double h, long *failed_at) {
    long k, j;
    for (k = k0; k < k1; k++) {
        *failed_at = k;
        double t = t0 + h * (double)k;
        for (j = 0; j < n_ops; j++) {
            const Op *op = &ops[j];
            switch (op->kind) {
            case OP_ACCESS:
                if (((access_fn)op->fn)(op->handle, op->vrs, op->n, op->base + k * op->row) > 1) return j;
                break;
            case OP_COPY_F64:
                *(double *)op->target = *(const double *)(op->base + k * op->row);
                break;
            case OP_COPY_I32:
                *(int32_t *)op->target = *(const int32_t *)(op->base + k * op->row);
                break;
            case OP_BARRIER:
                if (k == last) return -1;
                break;
            case OP_STEP:
                if (((step_fn)op->fn)(op->handle, t, h, 1) > 1) return j;
                break;
            }
        }
    }
    return -1;
}
