// Vocabulary shared by the optimal-current solvers, the 2-D tables and the controller.
// Conventions (docs/spec/MATH.md): amplitude-invariant dq, peak values, PM flux on +d,
// electrical speed omega = p * w_m, T = 1.5 p (psi_d i_q - psi_q i_d).
#pragma once

namespace ipmsm {

// pi, without relying on M_PI (POSIX, not ISO C++; mingw-w64 hides it without _USE_MATH_DEFINES).
constexpr double kPi = 3.14159265358979323846;

// Which constraints shape the current command (the contract's `region` output).
enum class Region : int {
    zero_torque = 0,                // T = 0 (with i_d < 0 if the back-EMF alone exceeds V_max)
    mtpa = 1,                       // minimum current for the torque; voltage not limiting
    voltage_limit = 2,              // torque curve meets the voltage ellipse (Case ii)
    current_and_voltage_limit = 3,  // T_max where the current circle meets the voltage ellipse
    mtpv = 4,                       // T_max at the maximum-torque-per-voltage point
};

// A constant-inductance machine (or the local linearisation of a saturated one).
struct LinearMachine {
    double psi_m;  // PM flux linkage, Wb
    double L_d;    // H
    double L_q;    // H
    double R_s;    // Ohm
};

// Where the drive is now: what limits the current command.
struct OperatingLimits {
    double omega;  // electrical speed, rad/s (either sign)
    double V_max;  // peak phase voltage available, V (k_u u_dc / sqrt 3)
    double I_max;  // peak current limit, A
};

// A current in the dq frame, A.
struct CurrentPoint {
    double i_d, i_q;
};

// A current command and what it achieves.
struct CurrentCommand {
    double i_d = 0, i_q = 0;  // A
    double torque = 0;        // torque the command produces (model), N.m
    double torque_max = 0;    // largest |T| reachable at this speed, N.m (>= 0)
    Region region = Region::zero_torque;
    int iterations = 0;     // inductance-recursion / Newton iterations used
    bool feasible = true;   // false: no current satisfies both limits (above maximum speed)
    bool converged = true;  // false: an iteration did not converge (a fallback was used)

    // field(x, what x may hold) for every member, in a fixed order (a model's state,
    // fmi/model.hpp); r names the ranges: r.current (A), r.torque (N.m), r.region, r.count.
    template <class Field, class Ranges>
    void fields(Field&& field, const Ranges& r) {
        field(i_d, r.current), field(i_q, r.current), field(torque, r.torque), field(torque_max, r.torque);
        field(region, r.region), field(iterations, r.count), field(feasible);
        field(converged);
    }
};

inline double torque_factor(int pole_pairs) { return 1.5 * pole_pairs; }

// The temperatures (magnets, windings) both FMUs accept, K: -100 .. 300 degC. Outside this range
// the machine is not a working motor (an NdFeB magnet, enamelled copper).
constexpr double kTemperatureMin_K = 173.15, kTemperatureMax_K = 573.15;

}  // namespace ipmsm
