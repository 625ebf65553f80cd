/* The FMU's binary: a thin C layer in front of pythonfmu's, compiled by `grapefmu build-fmu`.

   pythonfmu's binary turns every Python exception into fmiFatal and then drops the Python slave, so
   the host's next call dereferences nothing; it can only report OK, Discard or Fatal; it does not load
   libpython, so a host that is not a Python program cannot use it. This layer
   - loads libpython (and, when no Python runs in the process, starts one with the FMU's recorded
     interpreter, so its packages are found) before pythonfmu's binary,
   - wraps each instance so that a NULL or foreign instance gets fmiError instead of a crash,
   - refuses steps past the stop time the host declared,
   - raises the status of a call to whatever the Python side asked for through grapefmu_refuse
     (the slave never raises, so pythonfmu never sees an exception), and
   - finalizes a Python it started when the process exits (before the libraries' destructors: without
     it, scipy's libgfortran aborts the host with "free(): corrupted unsorted chunks" at exit), and
   - releases pythonfmu's Python state before that binary's own exit code runs (release_inner_state).
   The forwarders for every other FMI function are generated from the FMI headers (shim.py). */
#define _GNU_SOURCE
#include <dlfcn.h>
#include <pthread.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <wchar.h>

#include FMI_HEADER

#define STATUS_OK 0
#define STATUS_ERROR 3
#define STATUS_FATAL 4
#define INNER_LIBRARY "libpythonfmu-export.so"
#define PYTHON_FILE "python.txt" /* in the resources: "libpython=PATH" and "python=PATH" lines */

typedef struct {
    void* inner;        /* pythonfmu's instance */
    int stop_defined;
    double stop_time;
    void* log;          /* the host's logger: fmi2CallbackLogger or fmi3LogMessageCallback */
    void* env;          /* its first argument */
    char name[128];
} Instance;

static __thread int pending;          /* the worst status the Python side asked for during the current call */
static __thread Instance* current;    /* the instance the current call is for */
#define ENTER(I) (pending = STATUS_OK, current = (I))

static void say(const Instance* I, int status, const char* fmt, ...);

/* Called by the Python side (ctypes): log `message` for the current call and make it return `status` or
   worse. The Python slave calls this instead of raising, so pythonfmu keeps its instance alive. */
__attribute__((visibility("default"))) void grapefmu_refuse(int status, const char* message)
{
    say(current, status, "%s", message ? message : "");
    if (status > pending) pending = status;
}

/* Called by the Python side: whether this binary is forwarding an FMI call on this thread (the same FMU extracted
   twice in one process is two binaries sharing one Python module: the one in the call takes the refusal). */
__attribute__((visibility("default"))) int grapefmu_in_call(void) { return current != NULL; }

static __thread double start_given;  /* the startTime of the current fmi3EnterInitializationMode call */

/* Called by the Python side during fmi3EnterInitializationMode: pythonfmu3 passes the start time on to nobody. */
__attribute__((visibility("default"))) double grapefmu_start_time(void) { return start_given; }

#if FMI_VERSION == 3
static __thread double reached; /* the FMU's time after the step the current fmi3DoStep refused */

/* Called by the Python side when it refuses a step: the time the FMU stays at, fmi3DoStep's lastSuccessfulTime. */
__attribute__((visibility("default"))) void grapefmu_reached(double t) { reached = t; }
#endif

static int settle(int status)
{
    int p = pending;
    pending = STATUS_OK;
    current = NULL;
    return p > status && status != STATUS_FATAL ? p : status;
}

static void* inner_library;
static pthread_mutex_t load_lock = PTHREAD_MUTEX_INITIALIZER;
static int release_registered; /* release_inner_state is an exit handler (once per load of this layer) */

static void say(const Instance* I, int status, const char* fmt, ...)
{
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (I && I->log) {
#if FMI_VERSION == 2
        ((fmi2CallbackLogger)I->log)(I->env, I->name, (fmi2Status)status, "grapefmu", "%s", msg);
#else
        ((fmi3LogMessageCallback)I->log)(I->env, (fmi3Status)status, "grapefmu", msg);
#endif
    } else {
        fprintf(stderr, "grapefmu FMU: %s\n", msg);
    }
}

/* "file:///a%20b/resources/" (FMI 2 URI) or "/a b/resources/" (FMI 3 path) -> "/a b/resources" */
static void resource_dir(const char* location, char* out, size_t n)
{
    const char* s = location ? location : "";
    if (strncmp(s, "file://", 7) == 0) s += 7;
    if (strncmp(s, "localhost/", 10) == 0) s += 9;
    size_t k = 0;
    for (; *s && k + 1 < n; s++) {
        if (s[0] == '%' && s[1] && s[2]) {
            char hex[3] = {s[1], s[2], 0};
            out[k++] = (char)strtol(hex, NULL, 16);
            s += 2;
        } else {
            out[k++] = *s;
        }
    }
    while (k > 1 && out[k - 1] == '/') k--;
    out[k] = 0;
}

static void recorded(const char* resources, const char* key, const char* env, char* out, size_t n)
{
    out[0] = 0;
    const char* e = getenv(env);
    if (e && *e) {
        snprintf(out, n, "%s", e);
        return;
    }
    char path[4096];
    snprintf(path, sizeof path, "%s/%s", resources, PYTHON_FILE);
    FILE* f = fopen(path, "r");
    if (!f) return;
    char line[4096];
    size_t klen = strlen(key);
    while (fgets(line, sizeof line, f)) {
        if (strncmp(line, key, klen) == 0 && line[klen] == '=') {
            line[strcspn(line, "\r\n")] = 0;
            snprintf(out, n, "%s", line + klen + 1);
        }
    }
    fclose(f);
}

/* atexit: runs before the loader calls the libraries' destructors */
static void stop_python(void)
{
    int (*ensure)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "PyGILState_Ensure");
    int (*fin)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "Py_FinalizeEx");
    ensure();
    fin();
}

/* pythonfmu's binary keeps its Python state in a global std::shared_ptr. At exit the C++ runtime destroys it
   (an exit handler registered when the binary was loaded) and then the binary's destructor function,
   finalizePythonInterpreter, assigns nullptr to it: its count is decremented a second time, in memory already
   freed. That write corrupted the heap and the host aborted at exit in scipy's libgfortran ("corrupted
   double-linked list": a Python host of the FMI 3.0 FMU 24 times in 24, of the FMI 2.0 one now and then;
   docs/reliability.md). Released first, from a handler registered after the binary was loaded and so run before
   its own, and when this layer is unloaded, the pointer is empty when both come, and neither frees anything. */
static void release_inner_state(void)
{
    void (*release)(void) = inner_library ? (void (*)(void))dlsym(inner_library, "finalizePythonInterpreter") : NULL;
    if (release) release();
}

/* libpython in the process, an interpreter running, pythonfmu's binary loaded. NULL or what is missing. */
static const char* load(const char* resources, char* why, size_t n)
{
    pthread_mutex_lock(&load_lock);
    const char* err = NULL;
    if (!dlsym(RTLD_DEFAULT, "Py_IsInitialized")) {
        char lib[4096];
        recorded(resources, "libpython", "GRAPEFMU_LIBPYTHON", lib, sizeof lib);
        if (!dlopen(lib[0] ? lib : "libpython3.11.so.1.0", RTLD_NOW | RTLD_GLOBAL) &&
            !dlopen("libpython3.11.so.1.0", RTLD_NOW | RTLD_GLOBAL)) {
            snprintf(why, n, "cannot load libpython 3.11 (tried '%s' from %s/%s and the library path): %s; "
                     "set GRAPEFMU_LIBPYTHON to its path", lib, resources, PYTHON_FILE, dlerror());
            err = why;
            goto done;
        }
    }
    int (*is_initialized)(void) = (int (*)(void))dlsym(RTLD_DEFAULT, "Py_IsInitialized");
    if (!is_initialized()) {
        /* A host without Python: start one as the FMU's recorded interpreter would start, so that its
           virtual environment (and the packages the FMU needs) is on sys.path. */
        char exe[4096];
        recorded(resources, "python", "GRAPEFMU_PYTHON", exe, sizeof exe);
        wchar_t* (*decode)(const char*, size_t*) = (wchar_t * (*)(const char*, size_t*))dlsym(RTLD_DEFAULT, "Py_DecodeLocale");
        void (*set_program)(const wchar_t*) = (void (*)(const wchar_t*))dlsym(RTLD_DEFAULT, "Py_SetProgramName");
        void (*init)(int) = (void (*)(int))dlsym(RTLD_DEFAULT, "Py_InitializeEx");
        void* (*save)(void) = (void* (*)(void))dlsym(RTLD_DEFAULT, "PyEval_SaveThread");
        if (exe[0]) set_program(decode(exe, NULL)); /* kept for the process's life, as Python requires */
        /* The ROS 2 wheels' .pth re-executes the interpreter at start-up to set LD_LIBRARY_PATH, which in
           an embedded interpreter ends the host; tell it that it has already run. */
        setenv("_ROS_WHEELS_BOOTSTRAP_COMPLETE", "1", 0);
        setenv("PYTHONUTF8", "1", 0); /* files are UTF-8 whatever locale the host runs in */
        init(0);
        save(); /* release the GIL: every FMI call takes it with PyGILState_Ensure */
        /* Finalize at process exit, not when the host unloads the FMU (a handler of a library runs when it
           is unloaded, and finalizing there left the heap to abort the host at exit): keep this library
           loaded while the interpreter it started lives. */
        Dl_info self;
        dladdr((void*)&grapefmu_refuse, &self);
        dlopen(self.dli_fname, RTLD_NOW | RTLD_NOLOAD | RTLD_NODELETE);
        atexit(stop_python);
    }
    if (!inner_library) {
        Dl_info self;
        char path[4096];
        dladdr((void*)&grapefmu_refuse, &self);
        snprintf(path, sizeof path, "%s", self.dli_fname);
        char* slash = strrchr(path, '/');
        snprintf(slash ? slash + 1 : path, sizeof path - (slash ? (size_t)(slash + 1 - path) : 0), "%s", INNER_LIBRARY);
        inner_library = dlopen(path, RTLD_NOW | RTLD_LOCAL);
        if (!inner_library) {
            snprintf(why, n, "cannot load %s: %s", path, dlerror());
            err = why;
        } else if (!release_registered) {
            atexit(release_inner_state);
            release_registered = 1;
        }
    }
done:
    pthread_mutex_unlock(&load_lock);
    return err;
}

/* The host unloads the FMU: unload pythonfmu's binary with it, so that loading the FMU again starts it afresh. */
__attribute__((destructor)) static void unload(void)
{
    release_inner_state();
    if (inner_library) dlclose(inner_library);
    inner_library = NULL;
}

static void* inner_function(const char* name)
{
    return inner_library ? dlsym(inner_library, name) : NULL;
}

static int past_stop(Instance* I, double t, double h)
{
    if (!I->stop_defined || !(t + h > I->stop_time + 1e-9 * (1.0 + (I->stop_time > 0 ? I->stop_time : -I->stop_time))))
        return 0;
    say(I, STATUS_ERROR, "doStep [%.9g, %.9g] s ends after the stop time %.9g s set by the host; step refused",
        t, t + h, I->stop_time);
    return 1;
}

#define INNER(name) ((name##TYPE*)inner_function(#name))

/* A new wrapper holding the host's logger, with libpython and pythonfmu's binary loaded; NULL (after
   logging why) when they cannot be. */
static Instance* open_instance(const char* name, const char* location, void* log, void* env)
{
    Instance* I = calloc(1, sizeof(Instance));
    if (!I) return NULL;
    I->log = log;
    I->env = env;
    snprintf(I->name, sizeof I->name, "%s", name ? name : "");
    char resources[4096], why[8192];
    resource_dir(location, resources, sizeof resources);
    const char* err = load(resources, why, sizeof why);
    if (err) {
        say(I, STATUS_ERROR, "%s", err);
        free(I);
        return NULL;
    }
    ENTER(I);
    return I;
}

/* The wrapper around pythonfmu's new instance, or NULL (everything freed, after logging) when the Python
   slave could not be made. */
static Instance* opened(Instance* I, void* inner, void (*free_inner)(void*))
{
    int failed = !inner || pending >= STATUS_ERROR;
    pending = STATUS_OK;
    current = NULL;
    if (!failed) {
        I->inner = inner;
        return I;
    }
    say(I, STATUS_ERROR, "the Python slave could not be created (see the log above)");
    if (inner) free_inner(inner);
    free(I);
    return NULL;
}

static void close_instance(Instance* I, void (*free_inner)(void*))
{
    if (!I) return;
    free_inner(I->inner);
    free(I);
}

/* The host's stop time, enforced on every step. */
static void set_stop(Instance* I, int defined, double stop)
{
    I->stop_defined = defined;
    I->stop_time = stop;
    ENTER(I);
}

#if FMI_VERSION == 2
#define FREE_INNER ((void (*)(void*))INNER(fmi2FreeInstance))

const char* fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char* fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions* functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn)
{
    Instance* I = open_instance(instanceName, fmuResourceLocation, functions ? (void*)functions->logger : NULL,
                                functions ? functions->componentEnvironment : NULL);
    if (!I) return NULL;
    return opened(I, INNER(fmi2Instantiate)(instanceName, fmuType, fmuGUID, fmuResourceLocation, functions,
                                            visible, loggingOn), FREE_INNER);
}

void fmi2FreeInstance(fmi2Component c) { close_instance((Instance*)c, FREE_INNER); }

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime)
{
    Instance* I = (Instance*)c;
    if (!I) return fmi2Error;
    set_stop(I, stopTimeDefined, stopTime);
    return (fmi2Status)settle(INNER(fmi2SetupExperiment)(I->inner, toleranceDefined, tolerance, startTime,
                                                         stopTimeDefined, stopTime));
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint)
{
    Instance* I = (Instance*)c;
    if (!I || past_stop(I, currentCommunicationPoint, communicationStepSize)) return fmi2Error;
    ENTER(I);
    return (fmi2Status)settle(INNER(fmi2DoStep)(I->inner, currentCommunicationPoint, communicationStepSize,
                                                noSetFMUStatePriorToCurrentPoint));
}

#else
#define FREE_INNER ((void (*)(void*))INNER(fmi3FreeInstance))

const char* fmi3GetVersion(void) { return fmi3Version; }

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate)
{
    Instance* I = open_instance(instanceName, resourcePath, (void*)logMessage, instanceEnvironment);
    if (!I) return NULL;
    return opened(I, INNER(fmi3InstantiateCoSimulation)(instanceName, instantiationToken, resourcePath, visible,
                                                        loggingOn, eventModeUsed, earlyReturnAllowed,
                                                        requiredIntermediateVariables, nRequiredIntermediateVariables,
                                                        instanceEnvironment, logMessage, intermediateUpdate),
                  FREE_INNER);
}

/* Co-simulation only: the other two kinds are refused. */
fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage)
{
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "grapefmu", "this FMU is co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption)
{
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "grapefmu", "this FMU is co-simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { close_instance((Instance*)instance, FREE_INNER); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime)
{
    Instance* I = (Instance*)instance;
    if (!I) return fmi3Error;
    set_stop(I, stopTimeDefined, stopTime);
    start_given = startTime;
    return (fmi3Status)settle(INNER(fmi3EnterInitializationMode)(I->inner, toleranceDefined, tolerance, startTime,
                                                                 stopTimeDefined, stopTime));
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean* eventHandlingNeeded,
                      fmi3Boolean* terminateSimulation, fmi3Boolean* earlyReturn, fmi3Float64* lastSuccessfulTime)
{
    Instance* I = (Instance*)instance;
    if (!I || past_stop(I, currentCommunicationPoint, communicationStepSize)) {
        if (lastSuccessfulTime) *lastSuccessfulTime = currentCommunicationPoint;
        return fmi3Error;
    }
    ENTER(I);
    reached = currentCommunicationPoint;
    /* pythonfmu3 sets none of the flags, and lastSuccessfulTime to the step's end whatever the status: this FMU never
       needs event handling, never returns early and never asks to terminate; a refused step leaves it where it was */
    fmi3Boolean ignored[3];
    fmi3Float64 inner_time;
    fmi3Status status = (fmi3Status)settle(INNER(fmi3DoStep)(I->inner, currentCommunicationPoint,
                                                             communicationStepSize, noSetFMUStatePriorToCurrentPoint,
                                                             &ignored[0], &ignored[1], &ignored[2], &inner_time));
    if (eventHandlingNeeded) *eventHandlingNeeded = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = fmi3False;
    if (lastSuccessfulTime)
        *lastSuccessfulTime = status <= fmi3Warning ? currentCommunicationPoint + communicationStepSize : reached;
    return status;
}

#endif

/* Generated forwarders follow. */
