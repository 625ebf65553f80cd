/* A co-simulation host that is not a Python program: loads an extracted FMU's binary, instantiates it,
   holds a base acceleration, steps and prints the outputs named on the command line, then terminates,
   frees the instance, unloads the binary and exits. Built for FMI 2 or 3 with -DFMI_VERSION.

   host EXTRACTED_DIR MODEL_IDENTIFIER STOP DT AX AZ VR_AX VR_AZ VR...   -> one line "t v1 v2 ..." per step */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if FMI_VERSION == 2
#include "fmi2Functions.h"
#define PLATFORM "linux64"
static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    va_list ap;
    va_start(ap, message);
    fprintf(stderr, "[%d] ", (int)status);
    vfprintf(stderr, message, ap);
    fprintf(stderr, "\n");
    va_end(ap);
}
#else
#include "fmi3Functions.h"
#define PLATFORM "x86_64-linux"
static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message)
{
    fprintf(stderr, "[%d] %s\n", (int)status, message);
}
#endif

#define GET(lib, name) name##TYPE* name = (name##TYPE*)dlsym(lib, #name); if (!name) { fprintf(stderr, "missing %s\n", #name); return 2; }
#define CHECK(call) do { int s_ = (int)(call); if (s_ > 1) { fprintf(stderr, "%s -> status %d\n", #call, s_); return 3; } } while (0)

int main(int argc, char** argv)
{
    if (argc < 10) { fprintf(stderr, "usage: see the comment at the top\n"); return 2; }
    const char* dir = argv[1];
    const char* ident = argv[2];
    double stop = atof(argv[3]), dt = atof(argv[4]), ax = atof(argv[5]), az = atof(argv[6]);
    unsigned int in_vr[2] = {(unsigned)atoi(argv[7]), (unsigned)atoi(argv[8])};
    int n_out = argc - 9;
    unsigned int* out_vr = calloc(n_out, sizeof(unsigned int));
    double* out = calloc(n_out, sizeof(double));
    for (int k = 0; k < n_out; k++) out_vr[k] = (unsigned)atoi(argv[9 + k]);
    char path[4096], resources[4096];
    snprintf(path, sizeof path, "%s/binaries/%s/%s.so", dir, PLATFORM, ident);
    void* lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 2; }
    double inputs[2] = {ax, az};
    int steps = (int)(stop / dt + 0.5);
#if FMI_VERSION == 2
    GET(lib, fmi2Instantiate) GET(lib, fmi2SetupExperiment) GET(lib, fmi2EnterInitializationMode)
    GET(lib, fmi2ExitInitializationMode) GET(lib, fmi2SetReal) GET(lib, fmi2GetReal) GET(lib, fmi2DoStep)
    GET(lib, fmi2Terminate) GET(lib, fmi2FreeInstance)
    snprintf(resources, sizeof resources, "file://%s/resources", dir);
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c = fmi2Instantiate("host", fmi2CoSimulation, "", resources, &cb, fmi2False, fmi2True);
    if (!c) { fprintf(stderr, "instantiate failed\n"); return 3; }
    CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2True, stop));
    CHECK(fmi2EnterInitializationMode(c));
    CHECK(fmi2ExitInitializationMode(c));
    for (int k = 0; k < steps; k++) {
        CHECK(fmi2SetReal(c, in_vr, 2, inputs));
        CHECK(fmi2DoStep(c, k * dt, dt, fmi2True));
        CHECK(fmi2GetReal(c, out_vr, n_out, out));
        printf("%.17g", (k + 1) * dt);
        for (int j = 0; j < n_out; j++) printf(" %.17g", out[j]);
        printf("\n");
    }
    CHECK(fmi2Terminate(c));
    fmi2FreeInstance(c);
#else
    GET(lib, fmi3InstantiateCoSimulation) GET(lib, fmi3EnterInitializationMode) GET(lib, fmi3ExitInitializationMode)
    GET(lib, fmi3SetFloat64) GET(lib, fmi3GetFloat64) GET(lib, fmi3DoStep) GET(lib, fmi3Terminate)
    GET(lib, fmi3FreeInstance)
    snprintf(resources, sizeof resources, "%s/resources/", dir);
    fmi3Instance c = fmi3InstantiateCoSimulation("host", "", resources, fmi3False, fmi3True, fmi3False, fmi3False,
                                                 NULL, 0, NULL, logger, NULL);
    if (!c) { fprintf(stderr, "instantiate failed\n"); return 3; }
    CHECK(fmi3EnterInitializationMode(c, fmi3False, 0.0, 0.0, fmi3True, stop));
    CHECK(fmi3ExitInitializationMode(c));
    for (int k = 0; k < steps; k++) {
        fmi3Boolean ev, term, early;
        fmi3Float64 last;
        CHECK(fmi3SetFloat64(c, in_vr, 2, inputs, 2));
        CHECK(fmi3DoStep(c, k * dt, dt, fmi3True, &ev, &term, &early, &last));
        CHECK(fmi3GetFloat64(c, out_vr, n_out, out, n_out));
        printf("%.17g", (k + 1) * dt);
        for (int j = 0; j < n_out; j++) printf(" %.17g", out[j]);
        printf("\n");
    }
    CHECK(fmi3Terminate(c));
    fmi3FreeInstance(c);
#endif
    dlclose(lib);
    free(out_vr);
    free(out);
    fprintf(stderr, "host: clean exit\n");
    return 0;
}
