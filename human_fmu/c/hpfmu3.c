/*
 * hpfmu3.c: FMI 3.0 co-simulation interface of the hpcosim human side, around the same core
 * as the FMI 2.0 interface (hpfmu_core.inc: the hybrid integration, checks and outputs).
 *
 * Differences from FMI 2.0 (hpfmu.c), all from the standard:
 *   - value references are unique over all variables: Float64 from HPFMU3_VR_BASE_REAL,
 *     Int32 from HPFMU3_VR_BASE_INTEGER, Boolean from HPFMU3_VR_BASE_BOOLEAN, String from
 *     HPFMU3_VR_BASE_STRING (hpfmu_config.h, written with modelDescription.xml from one
 *     table), and the independent variable `time` is HPFMU3_VR_TIME;
 *   - fmi3EnterInitializationMode takes the start time (no fmi2SetupExperiment);
 *   - no event mode (hasEventMode = false): after fmi3ExitInitializationMode the instance
 *     is in step mode;
 *   - the end of a walk: the doStep during which the walker falls returns fmi3OK with
 *     *terminateSimulation = true and *lastSuccessfulTime = the time of the state held (the
 *     end of the step, or its start for fall codes 1, 5, 8, as in FMI 2.0); every later
 *     doStep returns fmi3Discard with *terminateSimulation = true and changes nothing.
 *     Every output keeps the last finite, physical state.
 * Functions of the other interface types (model exchange, scheduled execution), clocks,
 * derivatives and serialization return fmi3Error with a logged reason; getters and setters
 * of types the FMU has no variables of accept zero value references only.
 *
 * Rebuild (Linux, any C99 compiler), from the FMU's sources/ folder:
 *   cc -shared -fPIC -O2 -fno-math-errno -ffp-contract=off -fvisibility=hidden \
 *      -I. hpfmu3.c -o hpcosim_human.so -lm
 */

#include <math.h>
#include <stdbool.h>
#include <stdint.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#define HP_API_FIELDS fmi3LogMessageCallback logger; fmi3InstanceEnvironment env;
#define HP_EMIT(c, st, cat, msg) (c)->logger((c)->env, (fmi3Status)(st), cat, msg)
#include "hpfmu_core.inc"

/* the index in the type's array of an FMI 3.0 value reference, -1 if it is not one */
static long index_of(fmi3ValueReference vr, unsigned long base, unsigned long n) {
    return (vr >= base && (unsigned long)vr - base < n) ? (long)(vr - base) : -1;
}

static fmi3Status count_mismatch(Inst *c, const char *fn, size_t nvr, size_t nValues) {
    if (nValues == nvr) return fmi3OK;
    logmsg(c, HP_ERROR, "logStatusError", "%s: %lu values for %lu value references (every "
           "variable is a scalar)", fn, (unsigned long)nValues, (unsigned long)nvr);
    return fmi3Error;
}

static fmi3Status unknown_vr(Inst *c, const char *fn, fmi3ValueReference vr) {
    logmsg(c, HP_ERROR, "logStatusError", "%s: unknown value reference %lu", fn,
           (unsigned long)vr);
    return fmi3Error;
}

static fmi3Status unsupported(fmi3Instance instance, const char *what) {
    return (fmi3Status)fail((Inst *)instance, "%s is not supported", what);
}

/* -- common functions ------------------------------------------------------------------------ */
const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    Inst *c = (Inst *)instance;
    (void)nCategories;
    (void)categories;
    if (c == NULL) return fmi3Error;
    c->logging_on = loggingOn ? 1 : 0;
    return fmi3OK;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible,
                                          fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "hpcosim_human supports co-simulation only");
    return NULL;
}

fmi3Instance fmi3InstantiateCoSimulation(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
    fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
    size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    Inst *c;
    (void)resourcePath; (void)visible; (void)earlyReturnAllowed;
    (void)requiredIntermediateVariables; (void)intermediateUpdate;
    if (instantiationToken == NULL || strcmp(instantiationToken, HPFMU_GUID) != 0) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "instantiation token mismatch: the binary does not belong to this "
                       "modelDescription");
        return NULL;
    }
    if (eventModeUsed || nRequiredIntermediateVariables > 0) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "hpcosim_human has no event mode and no intermediate variables "
                       "(events are handled inside doStep)");
        return NULL;
    }
    c = hp_alloc(instanceName);
    if (c == NULL) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError", "out of memory");
        return NULL;
    }
    c->logger = logMessage;
    c->env = instanceEnvironment;
    c->logging_on = loggingOn ? 1 : 0;
    return c;
}

fmi3Instance fmi3InstantiateScheduledExecution(
    fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
    fmi3Boolean visible, fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
    fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
    fmi3LockPreemptionCallback lockPreemption, fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible;
    (void)loggingOn; (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage)
        logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                   "hpcosim_human supports co-simulation only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) { hp_free((Inst *)instance); }

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined,
                                       fmi3Float64 tolerance, fmi3Float64 startTime,
                                       fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Inst *c = (Inst *)instance;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (c == NULL) return fmi3Error;
    if (c->s.mode != MODE_INSTANTIATED)
        return (fmi3Status)fail(c, "%s: not in instantiated mode", "fmi3EnterInitializationMode");
    c->s.time = startTime;
    c->s.mode = MODE_INIT;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    Inst *c = (Inst *)instance;
    if (c == NULL) return fmi3Error;
    if (c->s.mode != MODE_INIT)
        return (fmi3Status)fail(c, "%s: not in initialization mode", "fmi3ExitInitializationMode");
    if (setup(c) != HP_OK) {
        c->s.mode = MODE_ERROR;
        return fmi3Error;
    }
    state_checks(c);  /* HybridSimulator checks the initial state too */
    c->s.mode = MODE_STEP;
    return fmi3OK;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterEventMode (no event mode)");
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    Inst *c = (Inst *)instance;
    if (c == NULL) return fmi3Error;
    c->s.mode = MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    Inst *c = (Inst *)instance;
    if (c == NULL) return fmi3Error;
    set_defaults(&c->s);
    return fmi3OK;
}

/* -- get/set of the types the FMU has ---------------------------------------------------------- */
/* the outputs among vr[] made current (evaluated once), or an error */
static fmi3Status ready(Inst *c, const char *fn, int need) {
    if (!need) return fmi3OK;
    if (!can_get(c)) {
        logmsg(c, HP_ERROR, "logStatusError", "%s: outputs need initialization mode", fn);
        return fmi3Error;
    }
    return prepare_outputs(c) == HP_OK ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    Inst *c = (Inst *)instance;
    size_t k;
    int need = 0;
    if (c == NULL) return fmi3Error;
    if (count_mismatch(c, "fmi3GetFloat64", nValueReferences, nValues)) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) {
        long i = index_of(valueReferences[k], HPFMU3_VR_BASE_REAL, HPFMU_N_REAL);
        if (valueReferences[k] == HPFMU3_VR_TIME) continue;
        if (i < 0) return unknown_vr(c, "fmi3GetFloat64", valueReferences[k]);
        if (HPFMU_REAL_KIND[i] == 'o') need = 1;
    }
    if (ready(c, "fmi3GetFloat64", need) != fmi3OK) return fmi3Error;
    for (k = 0; k < nValueReferences; k++)
        values[k] = valueReferences[k] == HPFMU3_VR_TIME
            ? c->s.time : c->s.r[valueReferences[k] - HPFMU3_VR_BASE_REAL];
    return fmi3OK;
}

fmi3Status fmi3GetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Int32 values[], size_t nValues) {
    Inst *c = (Inst *)instance;
    size_t k;
    int need = 0;
    if (c == NULL) return fmi3Error;
    if (count_mismatch(c, "fmi3GetInt32", nValueReferences, nValues)) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) {
        long i = index_of(valueReferences[k], HPFMU3_VR_BASE_INTEGER, HPFMU_N_INTEGER);
        if (i < 0) return unknown_vr(c, "fmi3GetInt32", valueReferences[k]);
        if (HPFMU_INTEGER_KIND[i] == 'o') need = 1;
    }
    if (ready(c, "fmi3GetInt32", need) != fmi3OK) return fmi3Error;
    for (k = 0; k < nValueReferences; k++)
        values[k] = c->s.i[valueReferences[k] - HPFMU3_VR_BASE_INTEGER];
    return fmi3OK;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Boolean values[], size_t nValues) {
    Inst *c = (Inst *)instance;
    size_t k;
    int need = 0;
    if (c == NULL) return fmi3Error;
    if (count_mismatch(c, "fmi3GetBoolean", nValueReferences, nValues)) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) {
        long i = index_of(valueReferences[k], HPFMU3_VR_BASE_BOOLEAN, HPFMU_N_BOOLEAN);
        if (i < 0) return unknown_vr(c, "fmi3GetBoolean", valueReferences[k]);
        if (HPFMU_BOOLEAN_KIND[i] == 'o') need = 1;
    }
    if (ready(c, "fmi3GetBoolean", need) != fmi3OK) return fmi3Error;
    for (k = 0; k < nValueReferences; k++)
        values[k] = c->s.b[valueReferences[k] - HPFMU3_VR_BASE_BOOLEAN] ? true : false;
    return fmi3OK;
}

fmi3Status fmi3GetString(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, fmi3String values[], size_t nValues) {
    Inst *c = (Inst *)instance;
    size_t k;
    if (c == NULL) return fmi3Error;
    if (count_mismatch(c, "fmi3GetString", nValueReferences, nValues)) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) {
        long i = index_of(valueReferences[k], HPFMU3_VR_BASE_STRING, HPFMU_N_STRING);
        if (i < 0) return unknown_vr(c, "fmi3GetString", valueReferences[k]);
        values[k] = HPFMU_STRING_START[i];
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[],
                          size_t nValues) {
    Inst *c = (Inst *)instance;
    size_t k;
    if (c == NULL) return fmi3Error;
    if (count_mismatch(c, "fmi3SetFloat64", nValueReferences, nValues)) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) {
        long i = index_of(valueReferences[k], HPFMU3_VR_BASE_REAL, HPFMU_N_REAL);
        if (valueReferences[k] == HPFMU3_VR_TIME)
            return (fmi3Status)fail(c, "variable %s cannot be set (independent)", "time");
        if (i < 0) return unknown_vr(c, "fmi3SetFloat64", valueReferences[k]);
        if (check_set(c, HPFMU_REAL_KIND[i], HPFMU_REAL_NAME[i]) != HP_OK) return fmi3Error;
    }
    for (k = 0; k < nValueReferences; k++)
        set_real(c, (unsigned)(valueReferences[k] - HPFMU3_VR_BASE_REAL), values[k]);
    c->s.outputs_valid = 0;
    return fmi3OK;
}

fmi3Status fmi3SetInt32(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Int32 values[], size_t nValues) {
    Inst *c = (Inst *)instance;
    size_t k;
    if (c == NULL) return fmi3Error;
    if (count_mismatch(c, "fmi3SetInt32", nValueReferences, nValues)) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) {
        long i = index_of(valueReferences[k], HPFMU3_VR_BASE_INTEGER, HPFMU_N_INTEGER);
        if (i < 0) return unknown_vr(c, "fmi3SetInt32", valueReferences[k]);
        if (check_set(c, HPFMU_INTEGER_KIND[i], HPFMU_INTEGER_NAME[i]) != HP_OK)
            return fmi3Error;
    }
    for (k = 0; k < nValueReferences; k++)
        c->s.i[valueReferences[k] - HPFMU3_VR_BASE_INTEGER] = values[k];
    c->s.outputs_valid = 0;
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Boolean values[],
                          size_t nValues) {
    Inst *c = (Inst *)instance;
    size_t k;
    if (c == NULL) return fmi3Error;
    if (count_mismatch(c, "fmi3SetBoolean", nValueReferences, nValues)) return fmi3Error;
    for (k = 0; k < nValueReferences; k++) {
        long i = index_of(valueReferences[k], HPFMU3_VR_BASE_BOOLEAN, HPFMU_N_BOOLEAN);
        if (i < 0) return unknown_vr(c, "fmi3SetBoolean", valueReferences[k]);
        if (check_set(c, HPFMU_BOOLEAN_KIND[i], HPFMU_BOOLEAN_NAME[i]) != HP_OK)
            return fmi3Error;
    }
    for (k = 0; k < nValueReferences; k++)
        c->s.b[valueReferences[k] - HPFMU3_VR_BASE_BOOLEAN] = values[k] ? 1 : 0;
    c->s.outputs_valid = 0;
    return fmi3OK;
}

fmi3Status fmi3SetString(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const fmi3String values[], size_t nValues) {
    Inst *c = (Inst *)instance;
    long i;
    (void)values;
    if (c == NULL) return fmi3Error;
    if (count_mismatch(c, "fmi3SetString", nValueReferences, nValues)) return fmi3Error;
    if (nValueReferences == 0) return fmi3OK;
    i = index_of(valueReferences[0], HPFMU3_VR_BASE_STRING, HPFMU_N_STRING);
    if (i < 0) return unknown_vr(c, "fmi3SetString", valueReferences[0]);
    return (fmi3Status)fail(c, "variable %s cannot be set (constant)", HPFMU_STRING_NAME[i]);
}

/* -- get/set of the types the FMU has no variables of --------------------------------------- */
static fmi3Status no_variables(fmi3Instance instance, const char *fn,
                               const fmi3ValueReference valueReferences[], size_t n) {
    Inst *c = (Inst *)instance;
    if (c == NULL) return fmi3Error;
    if (n == 0) return fmi3OK;
    return unknown_vr(c, fn, valueReferences[0]);
}

#define HP3_NO_VARIABLES(T)                                                                    \
    fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                          size_t nValueReferences, fmi3##T values[], size_t nValues) {       \
        (void)values; (void)nValues;                                                          \
        return no_variables(instance, "fmi3Get" #T, valueReferences, nValueReferences);      \
    }                                                                                          \
    fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference valueReferences[], \
                          size_t nValueReferences, const fmi3##T values[], size_t nValues) { \
        (void)values; (void)nValues;                                                          \
        return no_variables(instance, "fmi3Set" #T, valueReferences, nValueReferences);      \
    }

HP3_NO_VARIABLES(Float32)
HP3_NO_VARIABLES(Int8)
HP3_NO_VARIABLES(UInt8)
HP3_NO_VARIABLES(Int16)
HP3_NO_VARIABLES(UInt16)
HP3_NO_VARIABLES(UInt32)
HP3_NO_VARIABLES(Int64)
HP3_NO_VARIABLES(UInt64)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[],
                         size_t nValues) {
    (void)valueSizes; (void)values; (void)nValues;
    return no_variables(instance, "fmi3GetBinary", valueReferences, nValueReferences);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)valueSizes; (void)values; (void)nValues;
    return no_variables(instance, "fmi3SetBinary", valueReferences, nValueReferences);
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[]) {
    (void)values;
    return no_variables(instance, "fmi3GetClock", valueReferences, nValueReferences);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[]) {
    (void)values;
    return no_variables(instance, "fmi3SetClock", valueReferences, nValueReferences);
}

/* -- dependencies, FMU state, derivatives ------------------------------------------------------ */
fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance,
                                               fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference; (void)nDependencies;
    return unsupported(instance, "fmi3GetNumberOfVariableDependencies (modelDescription.xml "
                                 "lists them)");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents;
    (void)elementIndicesOfIndependents; (void)dependencyKinds; (void)nDependencies;
    return unsupported(instance, "fmi3GetVariableDependencies (modelDescription.xml lists "
                                 "them)");
}

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    Inst *c = (Inst *)instance;
    Data *copy;
    if (c == NULL || FMUState == NULL) return fmi3Error;
    copy = (Data *)(*FMUState ? *FMUState : xalloc(1, sizeof(Data)));
    if (copy == NULL) return (fmi3Status)fail(c, "fmi3GetFMUState: %s", "out of memory");
    *copy = c->s;
    *FMUState = copy;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    Inst *c = (Inst *)instance;
    if (c == NULL || FMUState == NULL) return fmi3Error;
    c->s = *(const Data *)FMUState;
    c->s.outputs_valid = 0;
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    (void)instance;
    if (FMUState == NULL) return fmi3OK;
    free(*FMUState);
    *FMUState = NULL;
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState,
                                      size_t *size) {
    (void)FMUState; (void)size;
    return unsupported(instance, "FMU state serialization");
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState,
                                 fmi3Byte serializedState[], size_t size) {
    (void)FMUState; (void)serializedState; (void)size;
    return unsupported(instance, "FMU state serialization");
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[],
                                   size_t size, fmi3FMUState *FMUState) {
    (void)serializedState; (void)size; (void)FMUState;
    return unsupported(instance, "FMU state serialization");
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance,
                                        const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed,
                                        fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    return unsupported(instance, "fmi3GetDirectionalDerivative");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                    size_t nUnknowns, const fmi3ValueReference knowns[],
                                    size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                                    fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed;
    (void)sensitivity; (void)nSensitivity;
    return unsupported(instance, "fmi3GetAdjointDerivative");
}

/* -- configuration mode, clocks, discrete states (none) ---------------------------------------- */
fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterConfigurationMode (no structural parameters)");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3ExitConfigurationMode (no structural parameters)");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance,
                                  const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    (void)intervals; (void)qualifiers;
    return no_variables(instance, "fmi3GetIntervalDecimal", valueReferences, nValueReferences);
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)counters; (void)resolutions; (void)qualifiers;
    return no_variables(instance, "fmi3GetIntervalFraction", valueReferences, nValueReferences);
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[]) {
    (void)shifts;
    return no_variables(instance, "fmi3GetShiftDecimal", valueReferences, nValueReferences);
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance,
                                const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
    (void)counters; (void)resolutions;
    return no_variables(instance, "fmi3GetShiftFraction", valueReferences, nValueReferences);
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance,
                                  const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[]) {
    (void)intervals;
    return no_variables(instance, "fmi3SetIntervalDecimal", valueReferences, nValueReferences);
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance,
                                   const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)counters; (void)resolutions;
    return no_variables(instance, "fmi3SetIntervalFraction", valueReferences, nValueReferences);
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[]) {
    (void)shifts;
    return no_variables(instance, "fmi3SetShiftDecimal", valueReferences, nValueReferences);
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance,
                                const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    (void)counters; (void)resolutions;
    return no_variables(instance, "fmi3SetShiftFraction", valueReferences, nValueReferences);
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    return unsupported(instance, "fmi3EvaluateDiscreteStates (no event mode)");
}

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation,
                                    fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged,
                                    fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    (void)discreteStatesNeedUpdate; (void)terminateSimulation;
    (void)nominalsOfContinuousStatesChanged; (void)valuesOfContinuousStatesChanged;
    (void)nextEventTimeDefined; (void)nextEventTime;
    return unsupported(instance, "fmi3UpdateDiscreteStates (no event mode)");
}

/* -- model exchange (not provided) -------------------------------------------------------------- */
fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    return unsupported(instance, "model exchange");
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance,
                                       fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode,
                                       fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint; (void)enterEventMode; (void)terminateSimulation;
    return unsupported(instance, "model exchange");
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    (void)time;
    return unsupported(instance, "model exchange");
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates; (void)nContinuousStates;
    return unsupported(instance, "model exchange");
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    (void)derivatives; (void)nContinuousStates;
    return unsupported(instance, "model exchange");
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[],
                                  size_t nEventIndicators) {
    (void)eventIndicators; (void)nEventIndicators;
    return unsupported(instance, "model exchange");
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    (void)continuousStates; (void)nContinuousStates;
    return unsupported(instance, "model exchange");
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    (void)nominals; (void)nContinuousStates;
    return unsupported(instance, "model exchange");
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    (void)nEventIndicators;
    return unsupported(instance, "model exchange");
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    (void)nContinuousStates;
    return unsupported(instance, "model exchange");
}

/* -- co-simulation ------------------------------------------------------------------------------ */
fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterStepMode (no event mode: step mode follows "
                                 "initialization)");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance,
                                    const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[],
                                    fmi3Float64 values[], size_t nValues) {
    (void)valueReferences; (void)nValueReferences; (void)orders; (void)values; (void)nValues;
    return unsupported(instance, "output derivatives");
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation,
                      fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    Inst *c = (Inst *)instance;
    int ended;
    hpStatus st;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (c == NULL) return fmi3Error;
    if (hp_check_step(c, "fmi3DoStep", currentCommunicationPoint, communicationStepSize)
        != HP_OK)
        return fmi3Error;
    ended = c->s.failed;
    st = hp_do_step(c, currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = false;
    if (earlyReturn) *earlyReturn = false;
    if (terminateSimulation) *terminateSimulation = c->s.failed ? true : false;
    if (lastSuccessfulTime)  /* after a fall: the time of the state held */
        *lastSuccessfulTime = c->s.failed ? c->s.time
                                          : currentCommunicationPoint + communicationStepSize;
    if (st == HP_DISCARD) return ended ? fmi3Discard : fmi3OK;  /* the fall itself: OK */
    return (fmi3Status)st;
}

/* -- scheduled execution (not provided) ---------------------------------------------------------- */
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    return unsupported(instance, "scheduled execution");
}
