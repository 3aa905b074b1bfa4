// Cost of one step of the machine's thermal network (fmu_src/thermal/motor_thermal.hpp): with the
// conditions held (the decomposition reused) and with the speed changing at every step (a new
// eigen-decomposition each step, the worst case of a drive cycle).
//   bench_thermal [steps]
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>

#include "thermal/motor_thermal.hpp"

using namespace ipmsm::thermal;

namespace {
double ns_per_step(bool speed_changes, long steps) {
    MotorThermal net(LptnParams(), 293.15);
    StepConditions at;
    at.w_m = 300.0, at.I_rms = 150.0, at.T_coolant = 323.15, at.T_ambient = 303.15;
    const double h = 1e-3;
    const auto t0 = std::chrono::steady_clock::now();
    for (long k = 0; k < steps; ++k) {
        if (speed_changes) at.w_m = 300.0 + 1e-3 * static_cast<double>(k % 100000);
        net.advance(h, 2.0 * h, 1.0 * h, at);
    }
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    if (!(net.theta(winding) > 0.0)) std::abort();  // keep the loop
    return 1e9 * s / static_cast<double>(steps);
}
}  // namespace

int main(int argc, char** argv) {
    const long steps = argc > 1 ? std::atol(argv[1]) : 1000000;
    for (int rep = 0; rep < 3; ++rep)
        std::printf("held conditions: %.0f ns/step; speed changing every step: %.0f ns/step\n",
                    ns_per_step(false, steps), ns_per_step(true, steps));
}
