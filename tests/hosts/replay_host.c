/* Runs the fit's compiled replay (pendulab.calibration._replay) from a DLL/shared library on inputs read from
 * in.bin, writes the states to out.bin: the win64 build of the fit's C, proven under Wine (tests/test_fit_win64.py).
 * in.bin: int32 m, n, n_free; double h; then x0[4], V[n], t[n], r[n], sr[n*4], P[m*n_free] (little-endian). */
#include <stdio.h>
#include <stdlib.h>
#include <windows.h>

typedef void (*run_t)(int, int, const double *, const double *, const double *, const double *, const double *,
                      const double *, double, double *);

static double *read_doubles(FILE *f, size_t count) {
    double *a = malloc(8 * count);
    if (!a || fread(a, 8, count, f) != count) exit(3);
    return a;
}

int main(int argc, char **argv) {
    int head[3];
    double h;
    FILE *f = fopen("in.bin", "rb");
    if (argc < 2 || !f || fread(head, 4, 3, f) != 3 || fread(&h, 8, 1, f) != 1) return 2;
    const int m = head[0], n = head[1], nf = head[2];
    double *x0 = read_doubles(f, 4), *V = read_doubles(f, n), *t = read_doubles(f, n), *r = read_doubles(f, n);
    double *sr = read_doubles(f, 4 * (size_t)n), *P = read_doubles(f, (size_t)m * nf);
    fclose(f);
    HMODULE library = LoadLibraryA(argv[1]);
    run_t run = library ? (run_t)GetProcAddress(library, "pendulab_run") : NULL;
    if (!run) { printf("cannot load %s: error %lu\n", argv[1], GetLastError()); return 1; }
    double *states = malloc(8 * 4 * (size_t)m * n);
    run(m, n, x0, V, t, r, sr, P, h, states);
    f = fopen("out.bin", "wb");
    fwrite(states, 8, 4 * (size_t)m * n, f);
    fclose(f);
    return 0;
}
