/* ipmsm_cosim: a native FMI 2.0 co-simulation master for IpmsmController + IpmsmPlant.
 *
 * Loaded from Python with ctypes (scenarios/master.py, backend "native"); usable from C as well.
 * It dlopens <unzip_dir>/binaries/linux64/<model_identifier>.so of each unzipped FMU, gets the
 * FMI functions with dlsym and runs the Jacobi-coupled loop at a fixed communication step h:
 *
 *   at t_k = k h:  plant.u_d,u_q <- controller.u_d_ref,u_q_ref (from the previous step, or from
 *                                   initialisation: the flying start)
 *                  controller.i_d,i_q <- plant.i_d,i_q (at t_k)
 *                  plant.doStep(t_k, h); controller.doStep(t_k, h); k += 1
 *                  read the outputs (coupling + probes) at t_{k+1}
 *
 * Units: 0 = the controller, 1 = the plant. Every function returning int returns 0 on success
 * and -1 on failure; the failure's text (which FMU, which FMI function, at which time, and the
 * FMU's log messages of that call) is then in ipmsm_cosim_error(). fmi2Warning counts as success
 * (its log messages go to the log callback). Time is always k*h with the integer k.
 */
#ifndef IPMSM_COSIM_H
#define IPMSM_COSIM_H

#include <stddef.h>

#ifdef __cplusplus
extern "C" {
#endif

#define IPMSM_COSIM_CONTROLLER 0
#define IPMSM_COSIM_PLANT 1

/* Probe kinds (ipmsm_cosim_probes) */
#define IPMSM_COSIM_REAL 0     /* a Real variable of the unit, by value reference */
#define IPMSM_COSIM_INTEGER 1  /* an Integer variable of the unit, by value reference (as double) */
#define IPMSM_COSIM_CURRENT_ABS 2 /* sqrt(i_d*i_d + i_q*i_q) of the plant's coupling outputs */
#define IPMSM_COSIM_CURRENT_SQ 3  /* i_d*i_d + i_q*i_q of the plant's coupling outputs */

/* Log callback: every message an FMU logs, after the FMI call that logged it returned (from the
 * thread that called the master). unit 0/1, status the fmi2Status, category and message as
 * logged (the message printf-formatted). NULL: messages with status >= fmi2Warning go to stderr. */
typedef void (*ipmsm_cosim_log_fn)(void* user, int unit, const char* instance, int status,
                                   const char* category, const char* message);

typedef struct ipmsm_cosim ipmsm_cosim;

/* A master with communication step h > 0. NULL if h is not a finite positive number. */
ipmsm_cosim* ipmsm_cosim_new(double h, ipmsm_cosim_log_fn log, void* user);
/* Terminates the initialised instances (unless an FMU reported fmi2Fatal), frees them, closes the
 * libraries and frees the master. NULL is accepted. */
void ipmsm_cosim_free(ipmsm_cosim* m);
/* The last failure's message ("" if none). Valid until the next call on m. */
const char* ipmsm_cosim_error(const ipmsm_cosim* m);

/* dlopen + dlsym + fmi2Instantiate (co-simulation, not visible). */
int ipmsm_cosim_instantiate(ipmsm_cosim* m, int unit, const char* unzip_dir, const char* model_identifier,
                            const char* guid, const char* instance_name, int logging_on);
/* fmi2SetupExperiment(no tolerance, start_time, no stop time) + fmi2EnterInitializationMode. */
int ipmsm_cosim_enter_initialization(ipmsm_cosim* m, int unit, double start_time);
int ipmsm_cosim_exit_initialization(ipmsm_cosim* m, int unit);

int ipmsm_cosim_set_real(ipmsm_cosim* m, int unit, size_t n, const unsigned* vr, const double* value);
int ipmsm_cosim_set_integer(ipmsm_cosim* m, int unit, size_t n, const unsigned* vr, const int* value);
int ipmsm_cosim_set_boolean(ipmsm_cosim* m, int unit, size_t n, const unsigned* vr, const int* value);
int ipmsm_cosim_set_string(ipmsm_cosim* m, int unit, size_t n, const unsigned* vr, const char* const* value);
int ipmsm_cosim_get_real(ipmsm_cosim* m, int unit, size_t n, const unsigned* vr, double* value);
int ipmsm_cosim_get_integer(ipmsm_cosim* m, int unit, size_t n, const unsigned* vr, int* value);

/* The coupling, after both units are initialised (reads the plant's i_d, i_q and the
 * controller's u_d_ref, u_q_ref once: the values the first step exchanges), at start_time = k0*h:
 *   controller_vr[8]: inputs T_ref, w_m, u_dc, T_magnet, i_d, i_q; outputs u_d_ref, u_q_ref
 *   plant_vr[7]:      inputs u_d, u_q, w_m, T_magnet, T_winding; outputs i_d, i_q          */
int ipmsm_cosim_couple(ipmsm_cosim* m, const unsigned* controller_vr, const unsigned* plant_vr, long long k0);

/* The outputs advance() reports (replaces the previous list): n probes, each (unit, kind, vr). */
int ipmsm_cosim_probes(ipmsm_cosim* m, size_t n, const int* unit, const int* kind, const unsigned* vr);

/* Runs n_steps >= 1 coupled steps with the slow inputs held:
 *   slow[5] = T_ref, w_m, u_dc, T_magnet (controller; w_m, T_magnet also the plant's), T_winding (plant)
 * set once at the start (controller: fmi2SetReal of T_ref, w_m, u_dc, T_magnet; plant: of w_m,
 * T_magnet, T_winding). Writes, per probe, mean[] = the sum over the steps of the value after
 * each step (summed in step order) / n_steps, and end[] = the value after the last step. If trace
 * is not NULL: decimation >= 1, and row r < n_steps / decimation of the row-major
 * trace[trace_rows][1 + n_probes] gets (t, probes...) after step (r + 1) * decimation.
 * Returns the number of trace rows written (0 without trace), or -1. A failure of a slow-input
 * set changes nothing (the master can be used again); a failure while stepping leaves the master
 * stopped at the failing step: later advances fail. */
long long ipmsm_cosim_advance(ipmsm_cosim* m, long long n_steps, const double* slow, double* mean, double* end,
                              double* trace, long long trace_rows, long long decimation);

/* Step index k and time k*h of the next step. */
long long ipmsm_cosim_step_index(const ipmsm_cosim* m);
double ipmsm_cosim_time(const ipmsm_cosim* m);

#ifdef __cplusplus
}
#endif

#endif
