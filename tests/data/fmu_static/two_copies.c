/* Two copies of the human FMU's sources, compiled with FMI2_FUNCTION_PREFIX hpA_ and hpB_
 * into static libraries, linked into this one program (tests/test_fmu_build.py).
 *
 * usage: two_copies GUID PERIODS VR...   prints, per copy, the outputs VR after PERIODS
 * 1 ms steps with zero prosthesis torque (or at the step the walk ended, fmi2Discard). */
#include <stdio.h>
#include <stdlib.h>

#include "fmi2FunctionTypes.h"

#define DECLARE(P)                                               \
    extern fmi2InstantiateTYPE P##fmi2Instantiate;               \
    extern fmi2SetupExperimentTYPE P##fmi2SetupExperiment;       \
    extern fmi2EnterInitializationModeTYPE P##fmi2EnterInitializationMode; \
    extern fmi2ExitInitializationModeTYPE P##fmi2ExitInitializationMode;   \
    extern fmi2DoStepTYPE P##fmi2DoStep;                         \
    extern fmi2GetRealTYPE P##fmi2GetReal;                       \
    extern fmi2TerminateTYPE P##fmi2Terminate;                   \
    extern fmi2FreeInstanceTYPE P##fmi2FreeInstance;

DECLARE(hpA_)
DECLARE(hpB_)

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status,
                   fmi2String category, fmi2String message, ...) {
    (void)env;
    (void)category;
    if (status > fmi2Warning) fprintf(stderr, "%s [%d] %s\n", name, (int)status, message);
}

#define WALK(P)                                                                          \
    do {                                                                                 \
        fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};                   \
        fmi2Component c = P##fmi2Instantiate(#P, fmi2CoSimulation, guid, "file:///tmp",  \
                                             &cb, fmi2False, fmi2False);                 \
        int k, ended = -1;                                                               \
        if (c == NULL) return 2;                                                         \
        if (P##fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0) != fmi2OK ||  \
            P##fmi2EnterInitializationMode(c) != fmi2OK ||                               \
            P##fmi2ExitInitializationMode(c) != fmi2OK) return 3;                        \
        for (k = 0; k < periods; k++) {                                                  \
            fmi2Status st = P##fmi2DoStep(c, k * 1e-3, 1e-3, fmi2True);                  \
            if (st == fmi2Discard) { ended = k; break; }                                 \
            if (st != fmi2OK) return 4;                                                  \
        }                                                                                \
        if (P##fmi2GetReal(c, vr, (size_t)n, out) != fmi2OK) return 5;                   \
        printf("%s ended %d", #P, ended);                                                \
        for (k = 0; k < n; k++) printf(" %.17g", out[k]);                                \
        printf("\n");                                                                    \
        P##fmi2Terminate(c);                                                             \
        P##fmi2FreeInstance(c);                                                          \
    } while (0)

int main(int argc, char **argv) {
    fmi2ValueReference vr[64];
    fmi2Real out[64];
    const char *guid;
    int periods, n, k;
    if (argc < 4 || argc - 3 > 64) return 1;
    guid = argv[1];
    periods = atoi(argv[2]);
    n = argc - 3;
    for (k = 0; k < n; k++) vr[k] = (fmi2ValueReference)strtoul(argv[3 + k], NULL, 10);
    WALK(hpA_);
    WALK(hpB_);
    return 0;
}
