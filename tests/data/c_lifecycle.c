/* A bare FMI 2.0 co-simulation host in C (for tests/test_fmu_lifecycle.py): drives
 * the call sequences of tests/lifecycle_host.py on every FMU of a job file, with
 * dlopen and no Python of its own (libpython is preloaded for the FMU, as any C
 * host must: LD_PRELOAD).
 *
 * usage: c_lifecycle JOBFILE
 * JOBFILE lines (whitespace-separated):
 *   FMU name unzipdir identifier guid h n_in vr value ... n_out vr ...
 *   SEQ name ops                   ops: letters as in tests/lifecycle_host.py
 *   MANY n i:op i:op ...           several instances of one FMU (n of them)
 *   PLAIN                          only the sequences above, nothing after them
 * Prints "BEGIN fmu sequence" before each sequence (flushed) and one JSON object
 * per sequence: {"fmu": ..., "seq": ..., "statuses": [...], "outputs": [[...], ...]};
 * then the sequence "all-at-once" over every FMU and "reload": the first FMU's
 * library unloaded and loaded again, then run. "DONE" at the end. */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef void* C;
typedef void (*Logger)(void*, const char*, int, const char*, const char*, ...);
typedef struct {
    Logger logger;
    void* (*alloc)(size_t, size_t);
    void (*release)(void*);
    void* step;
    void* env;
} Callbacks;

/* messages go to stderr (the test shows them when a sequence fails); statuses are what is checked */
static void logger(void* env, const char* name, int status, const char* category, const char* message, ...) {
    (void)env, (void)category;
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "LOG %s %d ", name, status);
    vfprintf(stderr, message, ap);
    fprintf(stderr, "\n");
    va_end(ap);
}

typedef struct {
    void* lib;
    C (*Instantiate)(const char*, int, const char*, const char*, const Callbacks*, int, int);
    void (*Free)(C);
    int (*Setup)(C, int, double, double, int, double);
    int (*Enter)(C);
    int (*Exit)(C);
    int (*Terminate)(C);
    int (*Reset)(C);
    int (*SetReal)(C, const unsigned*, size_t, const double*);
    int (*GetReal)(C, const unsigned*, size_t, double*);
    int (*DoStep)(C, double, double, int);
} Api;

#define MAXV 64
typedef struct {
    char name[256], unzip[2048], identifier[256], guid[256], uri[2100];
    double h;
    int n_in, n_out;
    unsigned vin[MAXV], vout[MAXV];
    double in[MAXV];
    Api api;
} Fmu;

#define MAXF 64
#define MAXS 64
static Fmu fmus[MAXF];
static int n_fmus = 0;
static char seq_names[MAXS][64], seq_ops[MAXS][64];
static int n_seqs = 0;
static int many_inst[128];
static char many_op[128];
static int n_many = 0;
static int plain = 0;
static Callbacks callbacks = {logger, calloc, free, NULL, NULL};

static int load(Fmu* f) {
    char path[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", f->unzip, f->identifier);
    Api* a = &f->api;
    a->lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!a->lib) {
        printf("dlopen: %s\n", dlerror());
        return 0;
    }
#define SYM(field, name)                                   \
    *(void**)(&a->field) = dlsym(a->lib, name);            \
    if (!a->field) {                                       \
        printf("missing %s\n", name);                      \
        return 0;                                          \
    }
    SYM(Instantiate, "fmi2Instantiate") SYM(Free, "fmi2FreeInstance") SYM(Setup, "fmi2SetupExperiment")
    SYM(Enter, "fmi2EnterInitializationMode") SYM(Exit, "fmi2ExitInitializationMode")
    SYM(Terminate, "fmi2Terminate") SYM(Reset, "fmi2Reset") SYM(SetReal, "fmi2SetReal")
    SYM(GetReal, "fmi2GetReal") SYM(DoStep, "fmi2DoStep")
#undef SYM
    return 1;
}

#define STEPS 3

typedef struct {
    char text[1 << 16];
    size_t len;
} Buf;

static void put(Buf* b, const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    int n = vsnprintf(b->text + b->len, sizeof b->text - b->len, fmt, ap);
    va_end(ap);
    if (n > 0 && b->len + (size_t)n < sizeof b->text) b->len += (size_t)n;
}

typedef struct {
    Buf statuses, outputs;
    int n_status, n_out;
} Record;

static void status(Record* r, int s) { put(&r->statuses, "%s%d", r->n_status++ ? ", " : "", s); }

/* one operation on instance slot c of FMU f; returns 0 when the host cannot go on */
static int op(Fmu* f, C* c, char letter, Record* r, const char* instance) {
    Api* a = &f->api;
    switch (letter) {
        case 'I':
            *c = a->Instantiate(instance, 1, f->guid, f->uri, &callbacks, 0, 0);
            status(r, *c ? 0 : 4);
            return *c != NULL;
        case 'F':
            a->Free(*c);
            *c = NULL;
            status(r, 0);
            return 1;
        case 'S': status(r, a->Setup(*c, 0, 0.0, 0.0, 0, 0.0)); return 1;
        case 'E': status(r, a->Enter(*c)); return 1;
        case 'X': status(r, a->Exit(*c)); return 1;
        case 'T': status(r, a->Terminate(*c)); return 1;
        case 'Z': status(r, a->Reset(*c)); return 1;
        case 'B': status(r, a->DoStep(*c, 0.0, -1.0, 1)); return 1;
        case 'R': {
            int worst = 0;
            for (int k = 0; k < STEPS; k++) {
                double y[MAXV];
                if (f->n_in) {
                    int s = a->SetReal(*c, f->vin, (size_t)f->n_in, f->in);
                    if (s > worst) worst = s;
                }
                int s = a->GetReal(*c, f->vout, (size_t)f->n_out, y);
                if (s > worst) worst = s;
                put(&r->outputs, "%s[", r->n_out++ ? ", " : "");
                for (int i = 0; i < f->n_out; i++) put(&r->outputs, "%s%.17g", i ? ", " : "", y[i]);
                put(&r->outputs, "]");
                s = a->DoStep(*c, k * f->h, f->h, 1);
                if (s > worst) worst = s;
            }
            status(r, worst);
            return 1;
        }
        default: printf("unknown op %c\n", letter); return 0;
    }
}

static void emit(const char* fmu, const char* seq, Record* r) {
    printf("{\"fmu\": \"%s\", \"seq\": \"%s\", \"statuses\": [%s], \"outputs\": [%s]}\n", fmu, seq,
           r->statuses.text, r->outputs.text);
    fflush(stdout);
}

static int read_job(const char* path) {
    FILE* in = fopen(path, "r");
    if (!in) return 0;
    char kind[16];
    while (fscanf(in, "%15s", kind) == 1) {
        if (strcmp(kind, "FMU") == 0 && n_fmus < MAXF) {
            Fmu* f = &fmus[n_fmus++];
            if (fscanf(in, "%255s %2047s %255s %255s %lf %d", f->name, f->unzip, f->identifier, f->guid, &f->h,
                       &f->n_in) != 6 || f->n_in > MAXV)
                return 0;
            for (int i = 0; i < f->n_in; i++)
                if (fscanf(in, "%u %lf", &f->vin[i], &f->in[i]) != 2) return 0;
            if (fscanf(in, "%d", &f->n_out) != 1 || f->n_out > MAXV) return 0;
            for (int i = 0; i < f->n_out; i++)
                if (fscanf(in, "%u", &f->vout[i]) != 1) return 0;
            char uri[sizeof f->uri];
            snprintf(uri, sizeof uri, "file://%s/resources", f->unzip);
            memcpy(f->uri, uri, sizeof uri);
        } else if (strcmp(kind, "SEQ") == 0 && n_seqs < MAXS) {
            if (fscanf(in, "%63s %63s", seq_names[n_seqs], seq_ops[n_seqs]) != 2) return 0;
            n_seqs++;
        } else if (strcmp(kind, "PLAIN") == 0) {
            plain = 1;
        } else if (strcmp(kind, "MANY") == 0) {
            int count;
            if (fscanf(in, "%d", &count) != 1 || count > 128) return 0;
            for (int i = 0; i < count; i++)
                if (fscanf(in, "%d:%c", &many_inst[i], &many_op[i]) != 2 || many_inst[i] < 0 || many_inst[i] > 7)
                    return 0;
            n_many = count;
        } else {
            return 0;
        }
    }
    fclose(in);
    return 1;
}

int main(int argc, char** argv) {
    if (argc != 2 || !read_job(argv[1])) {
        printf("bad job\n");
        return 2;
    }
    static Record r;
    for (int i = 0; i < n_fmus; i++) {
        Fmu* f = &fmus[i];
        if (!load(f)) return 3;
        for (int s = 0; s < n_seqs; s++) {
            printf("BEGIN %s %s\n", f->name, seq_names[s]);
            fflush(stdout);
            memset(&r, 0, sizeof r);
            C c = NULL;
            for (const char* o = seq_ops[s]; *o; o++)
                if (!op(f, &c, *o, &r, f->name)) return 4;
            emit(f->name, seq_names[s], &r);
        }
        if (n_many) {
            printf("BEGIN %s many\n", f->name);
            fflush(stdout);
            memset(&r, 0, sizeof r);
            C c[8] = {0};
            for (int k = 0; k < n_many; k++)
                if (!op(f, &c[many_inst[k]], many_op[k], &r, f->name)) return 4;
            emit(f->name, "many", &r);
        }
    }
    if (plain) {
        printf("DONE\n");
        return 0;
    }
    /* every FMU at once: created in order, every other one run, freed interleaved */
    printf("BEGIN * all-at-once\n");
    fflush(stdout);
    memset(&r, 0, sizeof r);
    C all[MAXF] = {0};
    for (int i = 0; i < n_fmus; i++)
        if (!op(&fmus[i], &all[i], 'I', &r, fmus[i].name)) return 4;
    for (int i = 0; i < n_fmus; i += 2)
        for (const char* o = "SEXR"; *o; o++) op(&fmus[i], &all[i], *o, &r, fmus[i].name);
    for (int i = (n_fmus - 1) - ((n_fmus - 1) % 2 == 0); i >= 1; i -= 2) op(&fmus[i], &all[i], 'F', &r, "");
    for (int i = 0; i < n_fmus; i += 2) op(&fmus[i], &all[i], 'F', &r, "");
    emit("*", "all-at-once", &r);
    /* a library unloaded and loaded again (as a host that closes an FMU and opens it later) */
    printf("BEGIN %s reload\n", fmus[0].name);
    fflush(stdout);
    memset(&r, 0, sizeof r);
    dlclose(fmus[0].api.lib);
    if (!load(&fmus[0])) return 3;
    C c = NULL;
    for (const char* o = "ISEXRTF"; *o; o++)
        if (!op(&fmus[0], &c, *o, &r, "reloaded")) return 4;
    emit(fmus[0].name, "reload", &r);
    printf("DONE\n");
    return 0;
}
