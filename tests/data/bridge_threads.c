/* A C host that instantiates the status bridge from several threads at once, with
 * stand-ins for the three CPython functions the bridge looks up in the process
 * (linked with -rdynamic, so that dlsym(RTLD_DEFAULT, ...) finds them). The
 * first thread to ask whether Python is running waits, up to a second, for the
 * others to ask too: a bridge that loads its inner library and starts the
 * interpreter without a lock lets them all in (two Py_InitializeEx at once crash
 * a host), a bridge with one lets in one. Prints the most threads seen inside at
 * once, how often the interpreter was started, and how many instances were made.
 *
 * usage: bridge_threads BRIDGE.so GUID RESOURCES_URI THREADS */
#include <dlfcn.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>

static atomic_int inside = 0, most_inside = 0, started_python = 0, n_threads = 0;

int Py_IsInitialized(void) {
    int now = atomic_fetch_add(&inside, 1) + 1;
    int seen = atomic_load(&most_inside);
    while (now > seen && !atomic_compare_exchange_weak(&most_inside, &seen, now)) {
    }
    struct timespec t0, t;
    clock_gettime(CLOCK_MONOTONIC, &t0);
    do { /* the others arrive here at once without a lock; with one they never do */
        struct timespec pause = {0, 1000000};
        nanosleep(&pause, NULL);
        clock_gettime(CLOCK_MONOTONIC, &t);
    } while (atomic_load(&inside) < atomic_load(&n_threads) && (t.tv_sec - t0.tv_sec) < 1);
    now = atomic_load(&inside);
    seen = atomic_load(&most_inside);
    while (now > seen && !atomic_compare_exchange_weak(&most_inside, &seen, now)) {
    }
    atomic_fetch_sub(&inside, 1);
    return atomic_load(&started_python) > 0;
}

void Py_InitializeEx(int handlers) {
    (void)handlers;
    atomic_fetch_add(&started_python, 1);
}

void* PyEval_SaveThread(void) { return NULL; }

typedef struct {
    void (*logger)(void*, const char*, int, const char*, const char*, ...);
    void* alloc;
    void* release;
    void* step;
    void* env;
} Callbacks;

typedef void* (*Instantiate)(const char*, int, const char*, const char*, const Callbacks*, int, int);
typedef void (*FreeInstance)(void*);

static void logger(void* env, const char* name, int status, const char* category, const char* message, ...) {
    (void)env, (void)name, (void)category;
    if (status >= 3) fprintf(stderr, "LOG %d %s\n", status, message);
}

static Instantiate instantiate;
static const char *guid, *uri;
static Callbacks callbacks = {logger, NULL, NULL, NULL, NULL};

static void* run(void* out) {
    *(void**)out = instantiate("thread", 1, guid, uri, &callbacks, 0, 0);
    return NULL;
}

int main(int argc, char** argv) {
    if (argc != 5) return 2;
    void* lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        fprintf(stderr, "%s\n", dlerror());
        return 3;
    }
    instantiate = (Instantiate)dlsym(lib, "fmi2Instantiate");
    FreeInstance free_instance = (FreeInstance)dlsym(lib, "fmi2FreeInstance");
    guid = argv[2], uri = argv[3];
    int n = atoi(argv[4]);
    if (!instantiate || !free_instance || n < 1 || n > 64) return 4;
    atomic_store(&n_threads, n);
    pthread_t threads[64];
    void* made[64] = {0};
    for (int i = 0; i < n; i++) pthread_create(&threads[i], NULL, run, &made[i]);
    int ok = 0;
    for (int i = 0; i < n; i++) {
        pthread_join(threads[i], NULL);
        if (made[i]) {
            ok++;
            free_instance(made[i]);
        }
    }
    printf("%d %d %d\n", atomic_load(&most_inside), atomic_load(&started_python), ok);
    return 0;
}
