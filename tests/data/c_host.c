/* A minimal FMI 2.0 co-simulation host in C (for the tests): loads an extracted
 * FMU, steps it with inputs p[1] = sin(0.25 k), w[1] = 0.3 and prints y[1] before
 * each doStep, then sets p[1] out of range and prints the status.
 * usage: c_host UNZIPDIR IDENTIFIER GUID VR_P VR_W VR_Y STEPS */
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

typedef void* C;
typedef void (*Logger)(void*, const char*, int, const char*, const char*, ...);
typedef struct { Logger logger; void* (*alloc)(size_t, size_t); void (*release)(void*); void* step; void* env; } Callbacks;

static void logger(void* env, const char* name, int status, const char* category, const char* message, ...) {
    (void)env; (void)category;
    va_list ap;
    va_start(ap, message);
    printf("LOG %s %d ", name, status);
    vprintf(message, ap);
    printf("\n");
    va_end(ap);
}

typedef C (*Instantiate)(const char*, int, const char*, const char*, const Callbacks*, int, int);
typedef int (*Setup)(C, int, double, double, int, double);
typedef int (*Mode)(C);
typedef int (*SetReal)(C, const unsigned*, size_t, const double*);
typedef int (*GetReal)(C, const unsigned*, size_t, double*);
typedef int (*DoStep)(C, double, double, int);
typedef void (*Free)(C);

#define SYM(T, n) T n = (T)dlsym(lib, #n); if (!n) { printf("missing %s\n", #n); return 2; }

int main(int argc, char** argv) {
    if (argc != 8) return 2;
    char path[4096], uri[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", argv[1], argv[2]);
    snprintf(uri, sizeof uri, "file://%s/resources", argv[1]);
    void* lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { printf("dlopen: %s\n", dlerror()); return 3; }
    SYM(Instantiate, fmi2Instantiate)
    SYM(Setup, fmi2SetupExperiment)
    SYM(Mode, fmi2EnterInitializationMode)
    SYM(Mode, fmi2ExitInitializationMode)
    SYM(SetReal, fmi2SetReal)
    SYM(GetReal, fmi2GetReal)
    SYM(DoStep, fmi2DoStep)
    SYM(Free, fmi2FreeInstance)
    Callbacks cb = {logger, calloc, free, NULL, NULL};
    C c = fmi2Instantiate("chost", 1, argv[3], uri, &cb, 0, 0);
    if (!c) { printf("instantiate failed\n"); return 4; }
    fmi2SetupExperiment(c, 0, 0.0, 0.0, 0, 0.0);
    fmi2EnterInitializationMode(c);
    int st = fmi2ExitInitializationMode(c);
    unsigned vin[2] = {(unsigned)atoi(argv[4]), (unsigned)atoi(argv[5])}, vy = (unsigned)atoi(argv[6]);
    int steps = atoi(argv[7]);
    for (int k = 0; k < steps && st == 0; k++) {
        double in[2] = {sin(0.25 * k), 0.3}, y;
        st = fmi2SetReal(c, vin, 2, in);
        st |= fmi2GetReal(c, &vy, 1, &y);
        printf("Y %d %.17g\n", k, y);
        st |= fmi2DoStep(c, (double)k, 1.0, 1);
    }
    double bad = 1.5;
    printf("BADSTATUS %d\n", fmi2SetReal(c, vin, 1, &bad));
    fmi2FreeInstance(c);
    printf("FREED\n");
    return st;
}
