/* ipmsm_cosim: the native FMI 2.0 co-simulation master of the coupled drive.
 *
 * It couples the units of a coupling description (fmu_src/coupling/ipmsm_drive.coupling: which
 * units, which output feeds which input, which external input feeds which inputs, and the
 * semantics: Jacobi at a fixed step h, t_k = k h with the integer k), resolving every name to a
 * value reference from the units' modelDescription.xml. Loaded from Python with ctypes
 * (scenarios/master.py, backend "native"), whose backend "fmpy" makes the same FMI calls in the
 * same order; usable from C and C++ (cosim_check.cpp, bench/).
 *
 * Use: ipmsm_cosim_new, ipmsm_cosim_instantiate (every unit), ipmsm_cosim_enter_initialization,
 * parameters with ipmsm_cosim_set_*, ipmsm_cosim_initialize, ipmsm_cosim_probes, then
 * ipmsm_cosim_advance as often as needed; ipmsm_cosim_free.
 *
 * Units are named by their role in the description ("controller", "plant"). Every function
 * returning int returns 0 on success and -1 on failure; the failure's text (which FMU, which FMI
 * function, at which time, and the FMU's log messages of that call) is then in
 * ipmsm_cosim_error(). fmi2Warning counts as success (its log messages go to the log callback).
 */
#ifndef IPMSM_COSIM_H
#define IPMSM_COSIM_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

/* The external inputs of the drive (the vehicle side's), held over an ipmsm_cosim_advance. Each
 * field feeds the inputs the coupling description names for the external input of the same
 * name (w_m -> controller.w_m, plant.w_m); a description's external input must be one of them. */
typedef struct ipmsm_cosim_inputs {
    double T_ref;     /* N.m, torque command */
    double w_m;       /* rad/s, mechanical speed */
    double u_dc;      /* V, DC-link voltage */
    double T_magnet;  /* K */
    double T_winding; /* K */
} ipmsm_cosim_inputs;

/* Log callback: every message an FMU logs, after the FMI call that logged it returned (from the
 * thread that called the master): the unit's role and instance name, the fmi2Status, category
 * and message as logged (the message printf-formatted). NULL: messages with status >=
 * fmi2Warning go to stderr. */
typedef void (*ipmsm_cosim_log_fn)(void* user, const char* role, const char* instance, int status, const char* category,
                                   const char* message);

typedef struct ipmsm_cosim ipmsm_cosim;

/* A master for the coupling description `coupling` (its text) at communication step h > 0.
 * NULL if h is not a finite positive number or memory is short; a bad description is reported
 * by the first call that needs it (ipmsm_cosim_instantiate). */
ipmsm_cosim* ipmsm_cosim_new(const char* coupling, double h, ipmsm_cosim_log_fn log, void* user);
/* Terminates the initialised instances (unless an FMU reported fmi2Fatal), frees them, closes the
 * libraries and frees the master. NULL is accepted. */
void ipmsm_cosim_free(ipmsm_cosim* m);
/* The last failure's message ("" if none). Valid until the next call on m. */
const char* ipmsm_cosim_error(const ipmsm_cosim* m);

/* Reads <unzip_dir>/modelDescription.xml, dlopens <unzip_dir>/binaries/linux64/<model
 * identifier>.so and calls fmi2Instantiate (co-simulation, not visible) for the unit `role`. */
int ipmsm_cosim_instantiate(ipmsm_cosim* m, const char* role, const char* unzip_dir, const char* instance_name,
                            int logging_on);
/* Every unit, in the description's order: fmi2SetupExperiment(no tolerance, t = 0, no stop time)
 * + fmi2EnterInitializationMode. Parameters can be set then. */
int ipmsm_cosim_enter_initialization(ipmsm_cosim* m);

int ipmsm_cosim_set_real(ipmsm_cosim* m, const char* role, size_t n, const unsigned* vr, const double* value);
int ipmsm_cosim_set_integer(ipmsm_cosim* m, const char* role, size_t n, const unsigned* vr, const int* value);
int ipmsm_cosim_set_boolean(ipmsm_cosim* m, const char* role, size_t n, const unsigned* vr, const int* value);
int ipmsm_cosim_set_string(ipmsm_cosim* m, const char* role, size_t n, const unsigned* vr, const char* const* value);
int ipmsm_cosim_get_real(ipmsm_cosim* m, const char* role, size_t n, const unsigned* vr, double* value);
int ipmsm_cosim_get_integer(ipmsm_cosim* m, const char* role, size_t n, const unsigned* vr, int* value);

/* The description's initialisation with the external inputs `start` at t = 0: unit by unit, one
 * fmi2SetReal of its external inputs and of its connected inputs from units already initialised,
 * fmi2ExitInitializationMode, one fmi2GetReal of its connected outputs. Then k = 0. */
int ipmsm_cosim_initialize(ipmsm_cosim* m, const ipmsm_cosim_inputs* start);

/* What ipmsm_cosim_advance reports (replaces the previous list), after initialisation: n names,
 * "ROLE.VARIABLE" (a Real or Integer variable, Integers as doubles), or "|i|" and "|i|^2":
 * sqrt(i_d^2 + i_q^2) and i_d^2 + i_q^2 of plant.i_d, plant.i_q. */
int ipmsm_cosim_probes(ipmsm_cosim* m, size_t n, const char* const* names);

/* Runs n_steps >= 1 coupled steps with the external inputs held, set once at the start (one
 * fmi2SetReal per unit, in the description's order). Each step k: one fmi2SetReal per
 * (receiving unit, sending unit) of the connected inputs; fmi2DoStep(k h, h) of every unit;
 * k += 1; fmi2GetReal (connected outputs, then Real probes) and fmi2GetInteger (Integer probes,
 * if any) of every unit. Writes, per probe, mean[] = the sum over the steps of the value after
 * each step (summed in step order) / n_steps, and end[] = the value after the last step. If
 * trace is not NULL: decimation >= 1, and row r < n_steps / decimation of the row-major
 * trace[trace_rows][1 + n_probes] gets (t, probes...) after step (r + 1) * decimation.
 * Returns the number of trace rows written (0 without trace), or -1. A refused external input
 * leaves k as it was (the master can be used again); a failure while stepping leaves the master
 * stopped at the failing step: later advances fail. */
long long ipmsm_cosim_advance(ipmsm_cosim* m, long long n_steps, const ipmsm_cosim_inputs* inputs, double* mean,
                              double* end, double* trace, long long trace_rows, long long decimation);

/* Step index k and time k*h of the next step. */
long long ipmsm_cosim_step_index(const ipmsm_cosim* m);
double ipmsm_cosim_time(const ipmsm_cosim* m);

#ifdef __cplusplus
}
#endif

#endif
