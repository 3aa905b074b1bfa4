// Discrete-time current regulator in rotor coordinates, written in flux linkage so that
// saturation does not change its dynamics, and designed directly in discrete time for its
// sample time h (the FMU's communication step, from microseconds to milliseconds), so that the
// one-sample computation delay and the rotation of the dq frame within a sample (omega h of
// several radians at top speed and 1 ms) are part of the design, not neglected.
//
// Plant, complex vectors in rotor coordinates (psi = psi_d + j psi_q; J = multiplication by j):
//     dpsi/dt = u - R_s i - j omega psi,   psi = psi(i) from the flux map.
// Over one sample with the dq voltage held (as the plant FMU holds its inputs) and R_s i taken
// as constant, its exact solution (hold equivalent) is
//     psi(k+1) = Phi psi(k) + Gamma (u - R_s i),   Phi = exp(-j omega h),
//     Gamma = (1 - Phi) / (j omega) = h g,   g = exp(-j omega h / 2) sin(omega h / 2) / (omega h / 2).
//
// One-sample delay, as in a digital drive and in FMI co-simulation: the voltage computed at t_k
// from the currents sampled at t_k is applied over [t_k + h, t_k + 2h]. The regulator therefore
// predicts the flux at t_k + h with the exact model and the voltage being applied now,
//     z(k) = Phi psi(k) + Gamma (u(k-1) - R_s i(k)),
// and commands
//     u(k) = R_s i(k+1) + j omega z(k) + g^-1 w(k),
// which turns the rotating plant into an integrator, z(k+1) = z(k) + h w(k), exactly: the
// feedforward is the back-EMF of the predicted flux, and g^-1 = e^(j omega h/2) (omega h/2) /
// sin(omega h/2) turns the voltage ahead by the half-sample rotation and scales it for the
// averaging over the sample. On that integrator a two-degree-of-freedom PI (reference r = the
// map's flux at the current command), in incremental form,
//     v <- v - c (r(k) - r(k-1)),   w(k) = k_p (r(k) - z(k)) + v,   v <- v + h k_i (r(k) - z(k)),
// with lambda = exp(-alpha_c h), c = (1 - lambda) / h, k_p = 2 c, k_i = c^2, puts both closed-
// loop poles at lambda and cancels one with the reference feedforward c: the flux (so the
// current) follows its reference as (1 - lambda) / (q - lambda), the sampled alpha_c / (s +
// alpha_c), without overshoot, on any map, at any h; the integrator removes what the model
// leaves out (R_s i changing within the sample, the plant's own integration). As h -> 0 this is
// the continuous IMC design of Harnefors and Nee (IEEE TIA 1998; flux-linkage based: Awan et
// al., IEEE TIA 2019), k_p -> 2 alpha_c, k_i -> alpha_c^2. For the direct discrete-time design
// of synchronous-frame current control with delay and frame rotation see Hinkkanen et al.,
// "Current control for synchronous motor drives: direct discrete-time pole-placement design",
// IEEE TIA 52(2), 2016, and motulator's discrete-time complex-vector controllers.
//
// Where the design stops: alpha_c above a quarter of the sampling rate, (pi / 2) / h, is lowered
// to it (lambda = e^(-pi/2) = 0.21), reported once through first_lowered_bandwidth(). In a
// sample in which the rotor turns by |omega h| >= kMaxRotationPerSample the loop cannot be
// closed (as omega h -> 2 pi the held voltage averages out over the turn, g -> 0, and no voltage
// in reach steers the flux): the regulator then commands the reference's steady-state voltage
// R_s i_ref + j omega psi(i_ref), holds its integrator, and says so (VoltageCommand::open_loop,
// first_open_loop()). The current commands stay valid: masters that use the controller only
// for them (at a vehicle step of 10 ms, say) are served.
//
// The voltage is limited to the inverter's linear range u_dc / sqrt 3 (SVPWM) keeping its angle,
// and the integrator is corrected by what the limit took away (anti-windup).
#pragma once

#include <cmath>
#include <limits>

#include "control/dq.hpp"
#include "machine/magnet_flux.hpp"

namespace ipmsm {

// 0.9 of a full electrical turn per sample: |g^-1| = 9.3 there (the regulator needs 9.3 times
// the voltage of a short sample for the same flux change), 1 ms covers 12 000 r/min with 4 pole
// pairs (omega h = 5.03 rad, |g^-1| = 4.3).
constexpr double kMaxRotationPerSample = 0.9 * 2.0 * 3.14159265358979323846;  // rad

// The largest alpha_c h: a quarter of the sampling rate 2 pi / h. Nearer deadbeat the loop acts
// on its model errors (the resistive drop and the current within the sample, the dq frame's
// turn) in one sample: coupled with the plant at 1 ms and 11 000 r/min (tests/python/
// test_step_size.py), alpha_c h = pi overshot the torque step by 4 % and the current reached
// 1.10 I_max within a sample; at pi / 2, 0.4 % and 0.97 I_max, settling as fast.
constexpr double kMaxBandwidthTimesStep = 3.14159265358979323846 / 2.0;

// The largest voltage magnitude the inverter applies linearly (SVPWM), V: u_dc / sqrt 3.
inline double linear_range(double u_dc) { return u_dc / std::sqrt(3.0); }

struct RegulatorState {
    Dq v;                 // integrator, V
    Dq u_prev;            // voltage being applied now, V
    Dq psi_ref;           // last reference flux (map at T_magnet_ref), Wb
    bool primed = false;  // psi_ref holds a previous reference

    // field(x, what x may hold) for every member, in a fixed order (a model's state,
    // fmi/model.hpp); the voltages only finite (the integrator is not bounded by the inverter).
    template <class Field, class Range>
    void fields(Field&& field, const Range& flux) {
        field(v.d), field(v.q), field(u_prev.d), field(u_prev.q), field(psi_ref.d, flux), field(psi_ref.q, flux);
        field(primed);
    }
};

struct VoltageCommand {
    double u_d, u_q;  // V
    bool limited;     // the inverter's linear range limited it
    bool open_loop;   // |omega h| >= kMaxRotationPerSample: the reference's steady-state voltage
};

class CurrentRegulator {
public:
    // bandwidth: closed-loop current bandwidth alpha_c, rad/s.
    CurrentRegulator(double bandwidth, double R_s) : alpha_c_(bandwidth), R_s_(R_s) {}

    // The voltage for the current command i_ref at the measured current i (A), the electrical
    // speed omega (rad/s), the DC link u_dc (V) and the sample time h (s).
    VoltageCommand step(Dq i_ref, Dq i, double omega, double u_dc, double h, const MagnetFlux& flux);

    // The bandwidth used at sample time h: alpha_c, or kMaxBandwidthTimesStep / h if lower.
    double bandwidth_at(double h) const;
    // bandwidth_at(h) < alpha_c: the sample time h cannot carry the bandwidth asked for.
    bool bandwidth_lowered(double h) const { return bandwidth_at(h) < alpha_c_; }
    // bandwidth_lowered(h), the first time only (to be logged once per instance).
    bool first_lowered_bandwidth(double h) { return first(bandwidth_lowered(h), reported_lowered_); }
    // A step's VoltageCommand::open_loop, the first time only.
    bool first_open_loop(const VoltageCommand& u) { return first(u.open_loop, reported_open_loop_); }
    double bandwidth() const { return alpha_c_; }
    // The stator resistance from now on (Ohm): the winding's at its present temperature.
    void set_resistance(double R_s) { R_s_ = R_s; }

    RegulatorState state;

private:
    // What the sample's rotation theta = omega h and the sample time h fix: they are held over a
    // communication step, so these are computed when they change, not at every sample.
    struct SampleConstants {
        double theta = std::numeric_limits<double>::quiet_NaN(), h = std::numeric_limits<double>::quiet_NaN();
        double cos_theta = 1, sin_theta = 0, cos_half = 1, sin_half = 0;  // of theta and theta / 2
        double g_abs = 1;                                                 // sinc(theta / 2)
        double lambda = 0;  // exp(-bandwidth_at(h) h), both closed-loop poles
    };
    const SampleConstants& constants(double theta, double h);
    SampleConstants constants_;
    // The reference's flux: the current command is held over a communication step, so the map
    // is evaluated there when the reference (or the map, or the magnet temperature) changes.
    struct ReferenceFlux {
        const FluxMap* map = nullptr;
        double i_d_ref = std::numeric_limits<double>::quiet_NaN(), i_q_ref = i_d_ref, shift = i_d_ref;
        FluxPoint at{};
    };
    const FluxPoint& reference_flux(double i_d_ref, double i_q_ref, const MagnetFlux& flux);
    ReferenceFlux reference_;
    double alpha_c_;
    double R_s_;
    bool reported_lowered_ = false;
    bool reported_open_loop_ = false;
    static bool first(bool happens, bool& reported) {
        if (reported || !happens) return false;
        return reported = true;
    }
};

}  // namespace ipmsm
