// The cost of a plant step in each inverter state (issue 33: a step freewheeling or in ASC costs at
// most twice a switching step), without Python or FMI: PlantModel (the IpmsmPlant FMU's model) on
// the default map at its default tolerances, 100 us steps, at a few speeds:
//   switching     the steady voltage that holds a motoring current (the controller's flying start)
//   ASC           from that current, the short circuit's transient and steady state
//   freewheeling  from that current, the bridge's conduction (above its onset) or its blocking
//   switching u=0 the inputs u_d = u_q = 0 through the switching path: ASC's trajectory, whose
//                 cost is the transient's (the same integrator), not the state's
//   freewheel+0.1s freewheeling after the trip's first 0.1 s (1000 steps untimed): the
//                 conducting bridge's steady state without the trip's transient
//   ASC+0.3s      ASC after the trip's first 0.3 s (3000 steps untimed): the short circuit's
//                 ringing decayed (over L/R), its steady state
// Reports microseconds per step (best of `rounds`; the thread's CPU time, so that other processes
// on a shared machine do not count) and CVODE steps per step; and IpmsmDrive's do_step per inner
// step (100 us) with and without a fault.
//
//   bench_faults [rounds = 5] [steps = 2000]
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>

#include "drive/drive_model.hpp"
#include "plant_model.hpp"
#include "source_tree.hpp"

namespace {

fmi::Context context() {
    fmi::Context ctx;
    ctx.instance_name = "bench";
    ctx.resource_dir = ipmsm::source_path("fmu_src/resources");
    return ctx;
}

// The calling thread's CPU time, s.
double cpu_seconds() {
    timespec ts{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
    return static_cast<double>(ts.tv_sec) + 1e-9 * static_cast<double>(ts.tv_nsec);
}

// switching with the inputs u_d = u_q = 0: the same trajectory as ASC through the switching path
constexpr int kSwitchingAtZero = 3;

struct Cost {
    double us = 1e300, cvode_steps = 0;
};

// n plant steps of 100 us in `state` from a motoring current at w_m, after `settle` steps untimed.
Cost plant_cost(int state, double w_m, int n, int rounds, int settle = 0) {
    Cost best;
    for (int r = 0; r < rounds; ++r) {
        ipmsm::PlantModel p(context());
        p.w_m = w_m;
        p.i_d_start = -120.0;
        p.i_q_start = 150.0;
        p.exit_initialization();
        // the voltage that holds the start current: psi from the plant, u = R i + omega J psi
        const double om = p.motor.pole_pairs * w_m;
        p.u_d = p.motor.R_s * p.i_d - om * p.psi_q;
        p.u_q = p.motor.R_s * p.i_q + om * p.psi_d;
        if (state == kSwitchingAtZero) p.u_d = p.u_q = 0.0;  // the ASC's equations, switching
        p.inverter_state = state == kSwitchingAtZero ? 0 : state;
        double t = 0, steps = 0;
        for (int k = 0; k < settle; ++k, t += 1e-4) p.do_step(t, 1e-4);
        const double t0 = cpu_seconds();
        for (int k = 0; k < n; ++k) {
            p.do_step(t, 1e-4);
            t += 1e-4;
            steps += p.cvode_steps;
        }
        const double us = 1e6 * (cpu_seconds() - t0) / n;
        if (us < best.us) best = {us, steps / n};
    }
    return best;
}

double drive_cost(bool fault, int safe_state, double w_m, int n, int rounds) {
    double best = 1e300;
    for (int r = 0; r < rounds; ++r) {
        ipmsm::DriveModel d(context());
        d.T_ref = 100.0, d.w_m = w_m, d.u_dc = 355.0;
        d.T_magnet = d.T_winding = d.T_coolant = d.T_ambient = 293.15;
        d.safe_state = safe_state;
        d.exit_initialization();
        double t = 0;
        d.do_step(t, 1e-2);  // settle the regulator
        t += 1e-2;
        d.fault = fault;
        const double t0 = cpu_seconds();
        for (int k = 0; k < n / 10; ++k) {
            d.do_step(t, 1e-3);
            t += 1e-3;
        }
        best = std::min(best, 1e6 * (cpu_seconds() - t0) / (10.0 * (n / 10)));
    }
    return best;
}

}  // namespace

int main(int argc, char** argv) {
    const int rounds = argc > 1 ? std::atoi(argv[1]) : 5;
    const int n = argc > 2 ? std::atoi(argv[2]) : 2000;
    std::printf("IpmsmPlant (PlantModel), default map and tolerances, %d steps of 100 us, best of %d\n", n, rounds);
    std::printf("%-10s %-14s %10s %12s %10s\n", "r/min", "state", "us/step", "CVODE steps", "/switching");
    for (double rpm : {3000.0, 6000.0, 8000.0, 12000.0}) {
        const double w_m = rpm * 3.14159265358979323846 / 30.0;
        const Cost sw = plant_cost(0, w_m, n, rounds);
        const char* names[] = {"switching", "freewheeling", "ASC", "switching u=0", "freewheel+0.1s", "ASC+0.3s"};
        for (int s = 0; s < 6; ++s) {
            // the last rows: the safe states after the trip's transient (their steady states)
            const Cost c = s == 0   ? sw
                           : s == 4 ? plant_cost(1, w_m, n, rounds, 1000)
                           : s == 5 ? plant_cost(2, w_m, n, rounds, 3000)
                                    : plant_cost(s, w_m, n, rounds);
            std::printf("%-10.0f %-14s %10.3f %12.2f %10.2f\n", rpm, names[s], c.us, c.cvode_steps, c.us / sw.us);
        }
    }
    std::printf("\nIpmsmDrive (DriveModel::do_step), 1 ms steps, per inner step of 100 us, best of %d\n", rounds);
    std::printf("%-10s %-22s %10s %10s\n", "r/min", "fault", "us/step", "/no fault");
    for (double rpm : {3000.0, 8000.0}) {
        const double w_m = rpm * 3.14159265358979323846 / 30.0;
        const double none = drive_cost(false, 0, w_m, n, rounds);
        std::printf("%-10.0f %-22s %10.3f %10.2f\n", rpm, "none", none, 1.0);
        for (int s : {1, 2}) {
            const double c = drive_cost(true, s, w_m, n, rounds);
            std::printf("%-10.0f %-22s %10.3f %10.2f\n", rpm, s == 1 ? "freewheeling" : "ASC", c, c / none);
        }
    }
    return 0;
}
