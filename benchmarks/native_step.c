/*
 * Time the steps of one native FMU in a bare C host (benchmarks/native_bench.py
 * compiles and runs it; Linux). No Python in the process.
 *
 * usage: native_step LIBRARY GUID RESOURCES_URI STEPS REPEAT H [in:VR:AMP:OMEGA:OFFSET ...] [out:VR ...]
 *
 * Each input VR is set to OFFSET + AMP sin(OMEGA k) at sample k; a step is H (the sample time). Two loops of
 * STEPS samples, each the best of REPEAT runs (a fresh instance each run):
 *   full: fmi2SetReal (every input, one call), fmi2DoStep, fmi2GetReal (every output, one call)
 *   step: fmi2DoStep alone, the inputs held at their last values
 * Prints "BENCH <full ns per sample> <step ns per sample> <checksum of the outputs>".
 */
#define _POSIX_C_SOURCE 199309L
#include <dlfcn.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

typedef void* fmi2Component;
typedef unsigned int fmi2ValueReference;
typedef void (*Logger)(void*, const char*, int, const char*, const char*, ...);
typedef struct {
    Logger logger;
    void* (*allocate)(size_t, size_t);
    void (*release)(void*);
    void* step_finished;
    void* env;
} Callbacks;
typedef fmi2Component (*Instantiate)(const char*, int, const char*, const char*, const Callbacks*, int, int);
typedef void (*FreeInstance)(fmi2Component);
typedef int (*Setup)(fmi2Component, int, double, double, int, double);
typedef int (*Mode)(fmi2Component);
typedef int (*Values)(fmi2Component, const fmi2ValueReference*, size_t, double*);
typedef int (*SetValues)(fmi2Component, const fmi2ValueReference*, size_t, const double*);
typedef int (*DoStep)(fmi2Component, double, double, int);

#define MAX_VARS 1024

static void logger(void* env, const char* name, int status, const char* category, const char* message, ...) {
    (void)env;
    fprintf(stderr, "%s: %d %s %s\n", name, status, category, message);
}

static double now(void) {
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return (double)ts.tv_sec + 1e-9 * (double)ts.tv_nsec;
}

static void* need(void* lib, const char* name) {
    void* f = dlsym(lib, name);
    if (!f) {
        fprintf(stderr, "no %s\n", name);
        exit(2);
    }
    return f;
}

int main(int argc, char** argv) {
    if (argc < 7) {
        fprintf(stderr, "usage: native_step LIBRARY GUID RESOURCES_URI STEPS REPEAT H [in:VR:AMP:OMEGA:OFFSET] [out:VR]\n");
        return 2;
    }
    void* lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "%s\n", dlerror());
        return 2;
    }
    Instantiate instantiate = (Instantiate)need(lib, "fmi2Instantiate");
    FreeInstance free_instance = (FreeInstance)need(lib, "fmi2FreeInstance");
    Setup setup = (Setup)need(lib, "fmi2SetupExperiment");
    Mode enter = (Mode)need(lib, "fmi2EnterInitializationMode");
    Mode exit_init = (Mode)need(lib, "fmi2ExitInitializationMode");
    SetValues set_real = (SetValues)need(lib, "fmi2SetReal");
    Values get_real = (Values)need(lib, "fmi2GetReal");
    DoStep do_step = (DoStep)need(lib, "fmi2DoStep");

    long steps = atol(argv[4]);
    int repeat = atoi(argv[5]);
    double h = strtod(argv[6], NULL);
    fmi2ValueReference in_vr[MAX_VARS], out_vr[MAX_VARS];
    double amp[MAX_VARS], omega[MAX_VARS], offset[MAX_VARS], in[MAX_VARS], out[MAX_VARS];
    size_t n_in = 0, n_out = 0;
    for (int i = 7; i < argc; i++) {
        unsigned vr;
        if (n_in < MAX_VARS && sscanf(argv[i], "in:%u:%lf:%lf:%lf", &vr, &amp[n_in], &omega[n_in], &offset[n_in]) == 4)
            in_vr[n_in++] = vr;
        else if (n_out < MAX_VARS && sscanf(argv[i], "out:%u", &vr) == 1)
            out_vr[n_out++] = vr;
        else {
            fprintf(stderr, "bad argument %s\n", argv[i]);
            return 2;
        }
    }
    /* the input table, computed before timing */
    double* table = (double*)malloc(sizeof(double) * (size_t)(steps > 0 ? steps : 1) * (n_in ? n_in : 1));
    for (long k = 0; k < steps; k++)
        for (size_t j = 0; j < n_in; j++) table[k * (long)n_in + (long)j] = offset[j] + amp[j] * sin(omega[j] * (double)k);

    Callbacks cb = {logger, calloc, free, NULL, NULL};
    double best_full = 1e300, best_step = 1e300, checksum = 0.0;
    for (int r = 0; r < repeat; r++) {
        for (int mode = 0; mode < 2; mode++) {
            fmi2Component c = instantiate("bench", 1, argv[2], argv[3], &cb, 0, 0);
            if (!c || setup(c, 0, 0.0, 0.0, 0, 0.0) || enter(c) || exit_init(c)) {
                fprintf(stderr, "the FMU did not initialize\n");
                return 3;
            }
            double sum = 0.0;
            double t0 = now();
            if (mode == 0) {
                for (long k = 0; k < steps; k++) {
                    int st = n_in ? set_real(c, in_vr, n_in, &table[k * (long)n_in]) : 0;
                    st |= do_step(c, (double)k * h, h, 1);
                    st |= n_out ? get_real(c, out_vr, n_out, out) : 0;
                    if (st) {
                        fprintf(stderr, "status %d at sample %ld\n", st, k);
                        return 4;
                    }
                    for (size_t j = 0; j < n_out; j++) sum += out[j];
                }
            } else {
                for (size_t j = 0; j < n_in; j++) in[j] = table[j];
                if (n_in) set_real(c, in_vr, n_in, in);
                for (long k = 0; k < steps; k++)
                    if (do_step(c, (double)k * h, h, 1)) {
                        fprintf(stderr, "doStep failed at sample %ld\n", k);
                        return 4;
                    }
            }
            double dt = (now() - t0) / (double)steps;
            if (mode == 0) {
                if (dt < best_full) best_full = dt;
                checksum = sum;
            } else if (dt < best_step) {
                best_step = dt;
            }
            free_instance(c);
        }
    }
    printf("BENCH %.3f %.3f %.17g\n", best_full * 1e9, best_step * 1e9, checksum);
    free(table);
    dlclose(lib);
    return 0;
}
