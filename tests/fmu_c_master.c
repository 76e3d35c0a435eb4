/* A minimal FMI 2.0 co-simulation master in C, as tools like Simulink or OMSimulator drive an FMU
 * natively (no Python in the host process): load the FMU's binary, instantiate, initialize, step
 * with a held input, print the outputs of every communication point as CSV.
 *
 *   fmu_c_master UNZIPPED_DIR MODEL_IDENTIFIER GUID STEPS DT VR_IN=VALUE[,VR_IN=VALUE...] VR_OUT[,VR_OUT...]
 *
 * Built by tests/test_fmu.py against FMPy's copy of the FMI 2.0 headers. */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    (void)env;
    fprintf(stderr, "[%s] status %d %s: %s\n", instance, (int)status, category ? category : "", message);
}

#define LOAD(name) name##TYPE *name = (name##TYPE *)dlsym(lib, #name); \
    if (!name) { fprintf(stderr, "missing %s\n", #name); return 3; }

static int parse_list(const char *text, fmi2ValueReference *vr, fmi2Real *val, int max) {
    int n = 0;
    char *copy = strdup(text), *save = NULL;
    for (char *tok = strtok_r(copy, ",", &save); tok && n < max; tok = strtok_r(NULL, ",", &save)) {
        char *eq = strchr(tok, '=');
        vr[n] = (fmi2ValueReference)strtoul(tok, NULL, 10);
        if (val) val[n] = eq ? strtod(eq + 1, NULL) : 0.0;
        n++;
    }
    free(copy);
    return n;
}

int main(int argc, char **argv) {
    if (argc != 8) {
        fprintf(stderr, "usage: %s DIR MODEL_IDENTIFIER GUID STEPS DT VR=U[,..] VR_OUT[,..]\n", argv[0]);
        return 2;
    }
    const char *dir = argv[1], *id = argv[2], *guid = argv[3];
    int steps = atoi(argv[4]);
    double dt = strtod(argv[5], NULL);
    fmi2ValueReference vin[64], vout[256];
    fmi2Real uin[64], y[256];
    int nin = parse_list(argv[6], vin, uin, 64), nout = parse_list(argv[7], vout, NULL, 256);

    char path[4096], uri[4096];
    snprintf(path, sizeof path, "%s/binaries/linux64/%s.so", dir, id);
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "dlopen: %s\n", dlerror()); return 3; }
    LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
    LOAD(fmi2ExitInitializationMode) LOAD(fmi2SetReal) LOAD(fmi2GetReal) LOAD(fmi2DoStep)
    LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)

    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    snprintf(uri, sizeof uri, "file://%s/resources", dir);
    fmi2Component c = fmi2Instantiate("c_master", fmi2CoSimulation, guid, uri, &cb, fmi2False, fmi2True);
    if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 4; }
    if (fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK
        || fmi2EnterInitializationMode(c) != fmi2OK
        || fmi2SetReal(c, vin, nin, uin) != fmi2OK
        || fmi2ExitInitializationMode(c) != fmi2OK) { fprintf(stderr, "initialization failed\n"); return 5; }
    for (int k = 0; k <= steps; k++) {
        if (k > 0) {
            if (fmi2SetReal(c, vin, nin, uin) != fmi2OK) return 6;
            if (fmi2DoStep(c, (k - 1) * dt, dt, fmi2True) != fmi2OK) { fprintf(stderr, "fmi2DoStep failed\n"); return 7; }
        }
        if (fmi2GetReal(c, vout, nout, y) != fmi2OK) return 8;
        printf("%.17g", k * dt);
        for (int i = 0; i < nout; i++) printf(",%.17g", y[i]);
        printf("\n");
    }
    if (fmi2Terminate(c) != fmi2OK) return 9;
    fmi2FreeInstance(c);
    /* _exit, not return: with pythonfmu 0.7 a process whose embedded Python loaded scipy.linalg
     * aborts in the exit handlers ("free(): corrupted unsorted chunks" in scipy's libgfortran), also
     * for a ten-line pythonfmu slave that only imports scipy.linalg; README "FMU export", limits. */
    fflush(stdout);
    _exit(0);
}
