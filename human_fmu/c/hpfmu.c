/*
 * hpfmu.c: FMI 2.0 co-simulation interface of the hpcosim human side.
 *
 * The plant (12-DOF hybrid human-prosthesis model) and the human-side controller (feedback
 * linearization of the human outputs) are CasADi-generated C (hpfmu_casadi.inc, included
 * below); this file is the hybrid integration algorithm of hp_model/simulator.py
 * (HybridSimulator.run, mode "human") and the FMI 2.0 API around it:
 *
 *   doStep(t, H): the inputs (prosthesis motor torques) are held over the step;
 *     - friction-cone check with the new inputs (fall after cone_periods bad steps);
 *     - `substeps` RK4 steps of h = H / substeps (rk4k_human_<d>: the first stage given, the
 *       first step's from the friction-cone check's evaluation); a step ending with the
 *       swing sole below ground while tau >= guard_tau_min (from the entry in a domain
 *       of HPFMU_GUARD_FROM_ENTRY) is cut at the crossing (Illinois
 *       method on s in (0, 1], one RK4 step of length s h per iteration, |z| <= event_tol or
 *       event_iters iterations); the landing foot is rotated flat about its ankle; the impact
 *       map of the next domain gives qd+; the rest (1 - s) h is integrated in the new domain;
 *     - state checks at the end (non-finite, speed, hip height, tau backward, tau_max, stall) and the
 *       touchdown-pitch check; a fall ends the walk: the `fall` output is raised, doStep
 *       returns fmi2Discard (then and on every later call, whatever the inputs),
 *       fmi2GetBooleanStatus(fmi2Terminated) is true and
 *       fmi2GetRealStatus(fmi2LastSuccessfulTime) is the fall time, the time of the state
 *       held (the simulator's fall time): the end of the step, or its start when the step
 *       ended non-finite or blown up (codes 1, 8: the last finite state) or the friction
 *       cone ended it before integrating (code 5), so every output stays finite and
 *       physical (a non-finite torque input never replaces the torque held).
 *
 * No global mutable state: any number of instances may live in one process.
 *
 * Rebuild (Linux, any C99 compiler), from the FMU's sources/ folder:
 *   cc -shared -fPIC -O2 -fno-math-errno -ffp-contract=off -fvisibility=hidden \
 *      -I. hpfmu.c -o hpcosim_human.so -lm
 */

#include <math.h>
#include <stdint.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#define HP_API_FIELDS fmi2CallbackLogger logger; fmi2ComponentEnvironment env;
#define HP_EMIT(c, st, cat, msg) \
    (c)->logger((c)->env, (c)->name ? (c)->name : "hpcosim_human", (fmi2Status)(st), cat, msg)
#include "hpfmu_core.inc"

/* -- FMI 2.0 API ---------------------------------------------------------------------------- */
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible,
                              fmi2Boolean loggingOn) {
    Inst *c;
    (void)fmuResourceLocation;
    (void)visible;
    if (functions == NULL || functions->logger == NULL) return NULL;
    if (fmuType != fmi2CoSimulation) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError", "hpcosim_human supports co-simulation only");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, HPFMU_GUID) != 0) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError",
                          "GUID mismatch: the binary does not belong to this modelDescription");
        return NULL;
    }
    c = hp_alloc(instanceName);
    if (c == NULL) {
        functions->logger(functions->componentEnvironment, instanceName, fmi2Error,
                          "logStatusError", "out of memory");
        return NULL;
    }
    c->logger = functions->logger;
    c->env = functions->componentEnvironment;
    c->logging_on = loggingOn ? 1 : 0;
    return c;
}

void fmi2FreeInstance(fmi2Component comp) { hp_free((Inst *)comp); }

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    Inst *c = (Inst *)comp;
    (void)nCategories;
    (void)categories;
    if (c == NULL) return fmi2Error;
    c->logging_on = loggingOn ? 1 : 0;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined,
                               fmi2Real tolerance, fmi2Real startTime,
                               fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Inst *c = (Inst *)comp;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    if (c == NULL) return fmi2Error;
    if (c->s.mode != MODE_INSTANTIATED) return fail(c, "%s: not in instantiated mode",
                                                    "fmi2SetupExperiment");
    c->s.time = startTime;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    if (c->s.mode != MODE_INSTANTIATED)
        return fail(c, "%s: not in instantiated mode", "fmi2EnterInitializationMode");
    c->s.mode = MODE_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    if (c->s.mode != MODE_INIT)
        return fail(c, "%s: not in initialization mode", "fmi2ExitInitializationMode");
    if (setup(c) != HP_OK) {
        c->s.mode = MODE_ERROR;
        return fmi2Error;
    }
    state_checks(c);  /* HybridSimulator checks the initial state too */
    c->s.mode = MODE_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    c->s.mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    set_defaults(&c->s);
    return fmi2OK;
}

/* -- get/set ---------------------------------------------------------------------------------- */
fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       fmi2Real value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    int need = 0;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_REAL) return fail(c, "fmi2GetReal: %s", "unknown value reference");
        if (HPFMU_REAL_KIND[vr[k]] == 'o') need = 1;
    }
    if (need) {
        if (!can_get(c)) return fail(c, "fmi2GetReal: %s", "outputs need initialization mode");
        if (prepare_outputs(c) != HP_OK) return fmi2Error;
    }
    for (k = 0; k < nvr; k++) value[k] = c->s.r[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Integer value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    int need = 0;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_INTEGER)
            return fail(c, "fmi2GetInteger: %s", "unknown value reference");
        if (HPFMU_INTEGER_KIND[vr[k]] == 'o') need = 1;
    }
    if (need) {
        if (!can_get(c)) return fail(c, "fmi2GetInteger: %s", "outputs need initialization mode");
        if (prepare_outputs(c) != HP_OK) return fmi2Error;
    }
    for (k = 0; k < nvr; k++) value[k] = c->s.i[vr[k]];
    return fmi2OK;
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          fmi2Boolean value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    int need = 0;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_BOOLEAN)
            return fail(c, "fmi2GetBoolean: %s", "unknown value reference");
        if (HPFMU_BOOLEAN_KIND[vr[k]] == 'o') need = 1;
    }
    if (need) {
        if (!can_get(c)) return fail(c, "fmi2GetBoolean: %s", "outputs need initialization mode");
        if (prepare_outputs(c) != HP_OK) return fmi2Error;
    }
    for (k = 0; k < nvr; k++) value[k] = c->s.b[vr[k]] ? fmi2True : fmi2False;
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                         fmi2String value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_STRING) return fail(c, "fmi2GetString: %s", "unknown value reference");
        value[k] = HPFMU_STRING_START[vr[k]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                       const fmi2Real value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_REAL) return fail(c, "fmi2SetReal: %s", "unknown value reference");
        if (check_set(c, HPFMU_REAL_KIND[vr[k]], HPFMU_REAL_NAME[vr[k]]) != HP_OK)
            return fmi2Error;
    }
    for (k = 0; k < nvr; k++) set_real(c, vr[k], value[k]);
    c->s.outputs_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Integer value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_INTEGER)
            return fail(c, "fmi2SetInteger: %s", "unknown value reference");
        if (check_set(c, HPFMU_INTEGER_KIND[vr[k]], HPFMU_INTEGER_NAME[vr[k]]) != HP_OK)
            return fmi2Error;
    }
    for (k = 0; k < nvr; k++) c->s.i[vr[k]] = value[k];
    c->s.outputs_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                          const fmi2Boolean value[]) {
    Inst *c = (Inst *)comp;
    size_t k;
    if (c == NULL) return fmi2Error;
    for (k = 0; k < nvr; k++) {
        if (vr[k] >= HPFMU_N_BOOLEAN)
            return fail(c, "fmi2SetBoolean: %s", "unknown value reference");
        if (check_set(c, HPFMU_BOOLEAN_KIND[vr[k]], HPFMU_BOOLEAN_NAME[vr[k]]) != HP_OK)
            return fmi2Error;
    }
    for (k = 0; k < nvr; k++) c->s.b[vr[k]] = value[k] ? 1 : 0;
    c->s.outputs_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                         const fmi2String value[]) {
    Inst *c = (Inst *)comp;
    (void)value;
    if (c == NULL) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (vr[0] >= HPFMU_N_STRING) return fail(c, "fmi2SetString: %s", "unknown value reference");
    return fail(c, "variable %s cannot be set (constant)", HPFMU_STRING_NAME[vr[0]]);
}

/* -- FMU state ---------------------------------------------------------------------------------- */
fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    Inst *c = (Inst *)comp;
    Data *copy;
    if (c == NULL || state == NULL) return fmi2Error;
    copy = (Data *)(*state ? *state : xalloc(1, sizeof(Data)));
    if (copy == NULL) return fail(c, "fmi2GetFMUstate: %s", "out of memory");
    *copy = c->s;
    *state = copy;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate state) {
    Inst *c = (Inst *)comp;
    if (c == NULL || state == NULL) return fmi2Error;
    c->s = *(const Data *)state;
    c->s.outputs_valid = 0;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *state) {
    (void)comp;
    if (state == NULL) return fmi2OK;
    free(*state);
    *state = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate state, size_t *size) {
    (void)state;
    (void)size;
    return fail((Inst *)comp, "%s is not supported", "FMU state serialization");
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate state, fmi2Byte bytes[],
                                 size_t size) {
    (void)state; (void)bytes; (void)size;
    return fail((Inst *)comp, "%s is not supported", "FMU state serialization");
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte bytes[], size_t size,
                                   fmi2FMUstate *state) {
    (void)bytes; (void)size; (void)state;
    return fail((Inst *)comp, "%s is not supported", "FMU state serialization");
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vUnknown[],
                                        size_t nUnknown, const fmi2ValueReference vKnown[],
                                        size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    (void)vUnknown; (void)nUnknown; (void)vKnown; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    return fail((Inst *)comp, "%s is not supported", "fmi2GetDirectionalDerivative");
}

/* -- co-simulation ------------------------------------------------------------------------------ */
fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[],
                                       size_t nvr, const fmi2Integer order[],
                                       const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    return fail((Inst *)comp, "%s is not supported (inputs are held)", "input derivatives");
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[],
                                        size_t nvr, const fmi2Integer order[],
                                        fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    return fail((Inst *)comp, "%s is not supported", "output derivatives");
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint,
                      fmi2Real communicationStepSize, fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Inst *c = (Inst *)comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (c == NULL) return fmi2Error;
    if (hp_check_step(c, "fmi2DoStep", currentCommunicationPoint, communicationStepSize)
        != HP_OK)
        return fmi2Error;
    return (fmi2Status)hp_do_step(c, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    return fail((Inst *)comp, "%s is not supported (doStep is synchronous)", "fmi2CancelStep");
}

fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value) {
    (void)s;
    (void)value;
    return fail((Inst *)comp, "%s is not supported", "fmi2GetStatus");
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {  /* after a fall: the time of the state held */
        *value = c->s.time;
        return fmi2OK;
    }
    return fail(c, "%s: only fmi2LastSuccessfulTime", "fmi2GetRealStatus");
}

fmi2Status fmi2GetIntegerStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s;
    (void)value;
    return fail((Inst *)comp, "%s is not supported", "fmi2GetIntegerStatus");
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s,
                                fmi2Boolean *value) {
    Inst *c = (Inst *)comp;
    if (c == NULL) return fmi2Error;
    if (s == fmi2Terminated) {  /* a fall ends the walk */
        *value = c->s.failed ? fmi2True : fmi2False;
        return fmi2OK;
    }
    return fail(c, "%s: only fmi2Terminated", "fmi2GetBooleanStatus");
}

fmi2Status fmi2GetStringStatus(fmi2Component comp, const fmi2StatusKind s, fmi2String *value) {
    (void)s;
    (void)value;
    return fail((Inst *)comp, "%s is not supported", "fmi2GetStringStatus");
}
