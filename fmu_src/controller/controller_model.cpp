#include "controller/controller_model.hpp"

#include <cmath>
#include <sstream>

#include "machine/machine.hpp"
#include "machine/magnet_flux.hpp"
#include "machine/map_file.hpp"
#include "machine/operating_region.hpp"
#include "parts/motor_map.hpp"
#include "parts/part_variables.hpp"

namespace ipmsm {

using fmi::Causality;
using fmi::Variability;
using V = fmi::Variable<ControllerModel>;
using M = ControllerModel;

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
constexpr double kSqrt3 = 1.7320508075688772;
}  // namespace

const std::vector<V>& ControllerModel::variables() {
    const auto motor = [](const char* name) { return fmi::part_variable(&M::motor, name); };
    static const std::vector<V> table = [&] {
        std::vector<V> t = {
            // inputs
            {"T_ref", &M::T_ref, Causality::input, Variability::continuous, "N.m", "", "Torque command (either sign)"},
            {"w_m", &M::w_m, Causality::input, Variability::continuous, "rad/s", "rpm",
             "Mechanical rotor speed (either sign)"},
            {"u_dc", &M::u_dc, Causality::input, Variability::continuous, "V", "", "Measured DC-link voltage", 0.0,
             kInf, true},
            {"i_d", &M::i_d, Causality::input, Variability::continuous, "A", "",
             "Measured d-axis current (peak, amplitude-invariant)"},
            {"i_q", &M::i_q, Causality::input, Variability::continuous, "A", "",
             "Measured q-axis current (peak, amplitude-invariant)"},
            {"T_magnet", &M::T_magnet, Causality::input, Variability::continuous, "K", "degC",
             "Magnet temperature (estimate)", kTemperatureMin_K, kTemperatureMax_K},
            // outputs
            {"i_d_ref", &M::i_d_ref, Causality::output, Variability::discrete, "A", "", "d-axis current command"},
            {"i_q_ref", &M::i_q_ref, Causality::output, Variability::discrete, "A", "", "q-axis current command"},
            {"u_d_ref", &M::u_d_ref, Causality::output, Variability::discrete, "V", "",
             "d-axis voltage command, within the inverter's linear range; to be applied over the next step"},
            {"u_q_ref", &M::u_q_ref, Causality::output, Variability::discrete, "V", "",
             "q-axis voltage command, within the inverter's linear range; to be applied over the next step"},
            {"T_cmd", &M::T_cmd, Causality::output, Variability::discrete, "N.m", "",
             "Torque actually commanded: T_ref clamped to what the limits allow now"},
            {"T_max", &M::T_max, Causality::output, Variability::discrete, "N.m", "",
             "Largest torque magnitude reachable now, with the sign of T_ref"},
            {"T_est", &M::T_est, Causality::output, Variability::discrete, "N.m", "",
             "Torque estimated from the measured currents and the flux map"},
            {"region", &M::region, Causality::output, Variability::discrete, "", "",
             "0 zero torque, 1 MTPA, 2 voltage limit (Case ii), 3 current and voltage limit, 4 MTPV"},
            {"iterations", &M::iterations, Causality::output, Variability::discrete, "", "",
             "Inductance-recursion (recursion 1) or Newton (recursion 2) iterations used this step"},
            {"voltage_saturated", &M::voltage_saturated, Causality::output, Variability::discrete, "", "",
             "The current regulator's voltage was limited to the inverter's linear range this step"},
            {"u_ratio", &M::u_ratio, Causality::output, Variability::discrete, "1", "",
             "Voltage command relative to the inverter's linear range u_dc/sqrt(3) (1: the regulator is "
             "voltage-limited)"},
            {"table_bytes", &M::table_bytes, Causality::output, Variability::discrete, "", "",
             "Memory of the 2-D tables (methods 2, 3), bytes; 0 for Ferrari"},
            // parameters
            {"method", &M::method, Causality::parameter, Variability::fixed, "", "",
             "1 Ferrari (online), 2 2-D table over torque x speed, 3 2-D table over torque x V_max/omega", 1, 3},
            {"recursion", &M::recursion, Causality::parameter, Variability::fixed, "", "",
             "0 nominal inductances, 1 apparent-inductance recursion (the paper), 2 optimal on the flux map", 0, 2},
            motor("flux_map"),
            motor("pole_pairs"),
            motor("R_s"),
            motor("I_max"),
            {"k_u", &M::k_u, Causality::parameter, Variability::fixed, "1", "",
             "Voltage utilisation of the current commands: V_max = k_u u_dc / sqrt(3)", 0.0, 1.0, true},
            motor("T_magnet_ref"),
            motor("k_psi_T"),
            {"lut_u_dc", &M::lut_u_dc, Causality::parameter, Variability::fixed, "V", "",
             "DC voltage the 2-D tables are built for (methods 2, 3)", 0.0, kInf, true},
            {"lut_T_magnet", &M::lut_T_magnet, Causality::parameter, Variability::fixed, "K", "degC",
             "Magnet temperature the 2-D tables are built for (methods 2, 3)", kTemperatureMin_K, kTemperatureMax_K},
            {"lut_n_torque", &M::lut_n_torque, Causality::parameter, Variability::fixed, "", "",
             "2-D table grid points along torque", 3, 1001},
            {"lut_n_speed", &M::lut_n_speed, Causality::parameter, Variability::fixed, "", "",
             "2-D table grid points along speed (method 2) or V_max/omega (method 3)", 3, 1001},
            {"w_m_max", &M::w_m_max, Causality::parameter, Variability::fixed, "rad/s", "rpm",
             "Top of the 2-D tables' speed axis", 0.0, kInf, true},
            {"current_bandwidth", &M::current_bandwidth, Causality::parameter, Variability::fixed, "rad/s", "",
             "Closed-loop bandwidth of the current regulator", 0.0, kInf, true},
            // appended: the value references above stay as they were
            {"command_check", &M::command_check, Causality::parameter, Variability::fixed, "", "",
             "1: a command that fails its check on the flux map is replaced by a checked one; 0: it is sent as the "
             "method made it, counted in check_failures and logged once (to study a method's own commands)",
             0, 1},
            {"check_failures", &M::check_failures, Causality::output, Variability::discrete, "", "",
             "Commands that failed the check on the flux map so far (each replaced by a checked one where found; the "
             "first is logged)"},
            // appended: the temperatures a drive uses (docs/thermal.md, "Controller")
            {"T_winding", &M::T_winding, Causality::input, Variability::continuous, "K", "degC",
             "Winding temperature (measured or estimated): the voltage limit and the current regulator use R = R_s (1 "
             "+ alpha_cu (T_winding - T_winding_ref))",
             kTemperatureMin_K, kTemperatureMax_K},
            {"derating", &M::derating, Causality::output, Variability::discrete, "1", "",
             "Thermal factor of the torque limit (1: none): T_max and the commands are this share of the machine's "
             "limit; it falls linearly from 1 at derating_margin below T_winding_max or T_magnet_max to 0 there"},
            motor("T_winding_ref"),
            motor("alpha_cu"),
            {"T_winding_max", &M::T_winding_max, Causality::parameter, Variability::fixed, "K", "degC",
             "Derating: winding temperature at which the torque limit reaches zero (default: IEC 60085 thermal class "
             "180 (H))",
             kTemperatureMin_K, kTemperatureMax_K},
            {"T_magnet_max", &M::T_magnet_max, Causality::parameter, Variability::fixed, "K", "degC",
             "Derating: magnet temperature at which the torque limit reaches zero (default: 150 degC, sintered NdFeB "
             "of the SH grades)",
             kTemperatureMin_K, kTemperatureMax_K},
            {"derating_margin", &M::derating_margin, Causality::parameter, Variability::fixed, "K", "degC",
             "Derating: the torque limit starts to fall this far below T_winding_max and T_magnet_max (default: 25 K, "
             "IEC 60085 class 155 (F) to 180 (H))",
             0.0, 1000.0, true, true},
            // least-loss control (docs/spec/INTERFACE.md, "Least-loss control"); the loss models'
            // parameters are the plant's parts, declared once (parts/part_variables.cpp)
            {"objective", &M::objective, Causality::parameter, Variability::fixed, "", "",
             "0 least current (the seed's), 1 least loss P_cu + P_fe + P_inv for the shaft torque (T_cmd and T_max "
             "are then shaft torques: T_e less the iron-loss drag)",
             0, 1},
            {"P_loss_cmd", &M::P_loss_cmd, Causality::output, Variability::discrete, "W", "",
             "The command's predicted steady-state loss P_cu + P_fe + P_inv at the present speed, u_dc and "
             "temperatures (either objective)"},
        };
        for (auto& v : fmi::part_variables(&M::iron_loss)) t.push_back(std::move(v));
        for (auto& v : fmi::part_variables(&M::inverter)) t.push_back(std::move(v));
        fmi::append_rest(t, &M::motor);
        return t;
    }();
    return table;
}

ControllerModel::ControllerModel(const fmi::Context& context) : context_(fmi::share(context)) {}

void ControllerModel::exit_initialization() {
    // Everything into locals first: a throw leaves the model as it was.
    if (const std::string e = winding_law_error(motor.alpha_cu, motor.T_winding_ref); !e.empty()) throw fmi::Error(e);
    const std::string path = flux_map_path(motor, *context_);
    const MotorMap loaded = load_motor_map(motor, path, *context_,
                                           [this](const std::string& p) { return fmi::parameter_number(*this, p); });
    std::shared_ptr<const FluxMap> map = loaded.map;
    check_current_limit_within_map(*map, motor.I_max);
    const FluxMapTable& t = map->table();
    SaturatedOptimalCurrent solver(map, motor.pole_pairs);
    std::optional<LeastLoss> least_loss;
    if (objective == 1) least_loss.emplace(map, motor.pole_pairs, solver.magnet_free());
    std::shared_ptr<const TorqueTable> table;
    if (method == 2 || method == 3) {
        TableSpec spec;
        spec.axis = method == 2 ? TableAxis::speed : TableAxis::flux;
        spec.n_torque = lut_n_torque;
        spec.n_second = lut_n_speed;
        spec.u_dc = lut_u_dc;
        spec.k_u = k_u;
        spec.I_max = motor.I_max;
        spec.R_s = motor.R_s;
        spec.psi_d_shift = magnet_flux_shift(*map, motor.k_psi_T, lut_T_magnet, motor.T_magnet_ref);
        spec.w_m_max = w_m_max;
        if (least_loss) {
            // least-loss tables: the least-loss solver at the table's u_dc, magnet temperature
            // and R_s (T_winding_ref), the node's speed
            SaturatedOptimalCurrent seeds = solver;
            const MagnetFlux flux(*map, spec.psi_d_shift);
            auto entry = [&](double T, const OperatingLimits& lim) {
                const CurrentCommand top =
                    seeds.solve(T < 0 ? -1e30 : 1e30, lim, spec.R_s, spec.psi_d_shift, Recursion::optimal);
                const CurrentCommand em = seeds.solve(T, lim, spec.R_s, spec.psi_d_shift, Recursion::optimal);
                const CurrentPoint hint{em.i_d, em.i_q};
                const DriveLoss loss(iron_loss, inverter, motor.pole_pairs, lim.omega / motor.pole_pairs, spec.R_s,
                                     spec.u_dc);
                return least_loss->solve(T, lim, flux, loss, top, &hint).cmd;
            };
            table = std::make_shared<const TorqueTable>(solver, spec, entry);
        } else {
            table = std::make_shared<const TorqueTable>(solver, spec);
        }
    }
    map_ = std::move(map);
    table_ = std::move(table);
    solver_ = std::move(solver);
    least_loss_ = std::move(least_loss);
    regulator_ = CurrentRegulator(current_bandwidth, motor.R_s);
    table_bytes = table_ ? static_cast<int>(table_->bytes()) : 0;
    initial_outputs();
    if (context_->log_info) {
        std::ostringstream os;
        os << "flux map " << quoted_excerpt(path) << ": " << t.i_d.size() << " x " << t.i_q.size()
           << " points, psi_m = " << map_->psi_m() << " Wb; method " << method << ", recursion " << recursion;
        if (table_) os << ", 2-D table " << lut_n_torque << " x " << lut_n_speed << " (" << table_bytes << " bytes)";
        context_->log_info(os.str());
    }
}

ControllerModel::Conditions ControllerModel::conditions() const {
    return {motor.pole_pairs * w_m, k_u * u_dc / kSqrt3,
            magnet_flux_shift(*map_, motor.k_psi_T, T_magnet, motor.T_magnet_ref), motor.resistance(T_winding),
            thermal_derating({T_winding_max, T_magnet_max, derating_margin}, T_winding, T_magnet)};
}

CurrentCommand ControllerModel::current_command(const Conditions& c) {
    if (cache_.holds(*this)) {
        CurrentCommand cmd = cache_.cmd;
        cmd.iterations = 0;
        return cmd;
    }
    CurrentCommand cmd = checked_command(T_ref, c);
    // Derating: the limit is c.derating of the machine's; a larger torque is commanded at it.
    if (c.derating < 1.0) {
        const double limit = c.derating * cmd.torque_max;
        if (std::abs(T_ref) > limit) {
            const int used = cmd.iterations;
            cmd = checked_command(std::copysign(limit, T_ref), c);
            cmd.iterations += used;
        }
        cmd.torque_max = limit;
    }
    return cmd;
}

CurrentCommand ControllerModel::checked_command(double T, const Conditions& c) {
    // Every command is checked on the map before it leaves (docs/controller.md): recursion 2's
    // inside the solver, the others against it. The 2-D tables are made at R_s (T_winding_ref)
    // and lut_T_magnet; their check is at the present temperatures.
    if (least_loss_) return least_loss_command(T, c);
    const OperatingLimits lim{c.omega, c.V_max, motor.I_max};
    CurrentCommand cmd;
    if (method == 1 && recursion == static_cast<int>(Recursion::optimal)) {
        cmd = solver_->solve(T, lim, c.R, c.shift, Recursion::optimal);
    } else {
        const CurrentCommand raw = method == 1 ? solver_->solve(T, lim, c.R, c.shift, static_cast<Recursion>(recursion))
                                               : table_->lookup(T, w_m, c.V_max);
        cmd = solver_->checked(raw, T, lim, c.R, c.shift);
    }
    if (solver_->last_check.finding != CheckFinding::passed) {
        report_check(solver_->last_check);
        if (command_check == 0 && solver_->last_check.replaced) {  // reported, sent as the method made it
            const int used = cmd.iterations;
            cmd = solver_->last_check.rejected;
            cmd.iterations = used;
        }
    }
    return cmd;
}

DriveLoss ControllerModel::drive_loss(const Conditions& c) const {
    return DriveLoss(iron_loss, inverter, motor.pole_pairs, w_m, c.R, u_dc);
}

CurrentCommand ControllerModel::least_loss_command(double T, const Conditions& c) {
    // Every method and recursion: the exact least-loss solver (control/least_loss.hpp), seeded by
    // recursion 2's checked least-current commands (its T_max point, and its command for T); the
    // 2-D tables (methods 2, 3) are least-loss tables, their commands checked against it.
    const OperatingLimits lim{c.omega, c.V_max, motor.I_max};
    const MagnetFlux flux(*map_, c.shift);
    const CurrentCommand top = solver_->solve(T < 0 ? -1e30 : 1e30, lim, c.R, c.shift, Recursion::optimal);
    const CurrentCommand em = solver_->solve(T, lim, c.R, c.shift, Recursion::optimal);
    const CurrentPoint hint{em.i_d, em.i_q};
    const DriveLoss loss = drive_loss(c);
    const LeastLossResult r = least_loss_->solve(T, lim, flux, loss, top, &hint);
    CurrentCommand cmd = r.cmd;
    cmd.iterations += top.iterations + em.iterations;
    if (table_) {
        // The least-loss table's command, checked against the exact one: its shaft torque, T_max,
        // the limits and its loss (docs/controller.md); where it fails, the exact command.
        const CurrentCommand raw = table_->lookup(T, w_m, c.V_max);
        const double kT = torque_factor(motor.pole_pairs), scale = std::max(r.cmd.torque_max, 1e-12);
        const FluxPoint f = flux.eval(raw.i_d, raw.i_q);
        const double T_shaft = kT * (f.psi_d * raw.i_q - f.psi_q * raw.i_d) -
                               loss.drag(loss.iron().power(motor.pole_pairs, w_m, f.psi_d, f.psi_q));
        const double T_cmd_exact = std::copysign(std::min(std::abs(T), r.cmd.torque_max), T);
        const double vd = c.R * raw.i_d - c.omega * f.psi_q, vq = c.R * raw.i_q + c.omega * f.psi_d;
        CheckFinding finding = CheckFinding::passed;
        if (!(std::isfinite(raw.i_d) && std::isfinite(raw.i_q))) finding = CheckFinding::not_finite;
        else if (std::hypot(raw.i_d, raw.i_q) > motor.I_max * (1.0 + SaturatedOptimalCurrent::kLimitTolerance))
            finding = CheckFinding::current_limit;
        else if (vd * vd + vq * vq > c.V_max * c.V_max * (1.0 + SaturatedOptimalCurrent::kLimitTolerance))
            finding = CheckFinding::voltage_limit;
        else if (std::abs(T_shaft - T_cmd_exact) > SaturatedOptimalCurrent::kTorqueTolerance * scale)
            finding = CheckFinding::torque;
        else if (std::abs(raw.torque_max - r.cmd.torque_max) > SaturatedOptimalCurrent::kTorqueTolerance * scale)
            finding = CheckFinding::torque_max;
        else if (std::abs(T) < r.cmd.torque_max &&
                 LeastLoss::loss_at(flux, loss, motor.pole_pairs, raw.i_d, raw.i_q).total() >
                     r.loss.total() * (1.0 + LeastLoss::kTableLossTolerance))
            finding = CheckFinding::not_least_loss;
        if (finding == CheckFinding::passed) {
            CurrentCommand out = raw;
            out.torque = T_shaft;
            out.iterations = cmd.iterations;
            return out;
        }
        CheckRecord record;
        record.finding = finding;
        record.rejected = raw;
        record.T_target = T_cmd_exact;
        record.T_made = T_shaft;
        record.replaced = true;
        report_check(record);
        if (command_check == 0) {
            CurrentCommand out = raw;
            out.torque = T_shaft;
            out.iterations = cmd.iterations;
            return out;
        }
        return cmd;
    }
    if (!r.check_passed) {
        CheckRecord record;
        record.finding = CheckFinding::not_least_loss;
        record.rejected = cmd;
        record.T_target = std::copysign(std::min(std::abs(T), cmd.torque_max), T);
        record.T_made = cmd.torque;
        record.replaced = r.searched;
        report_check(record);
    }
    return cmd;
}

void ControllerModel::report_check(const CheckRecord& r) {
    ++check_failures;
    if (warned_check_ || !context_->log_warning) return;
    warned_check_ = true;
    const CurrentCommand& x = r.rejected;
    std::ostringstream os;
    os << "command check failed (logged once; check_failures counts them): method " << method << ", recursion "
       << recursion << " commanded (" << x.i_d << ", " << x.i_q << ") A for T_ref = " << T_ref
       << " N.m at w_m = " << w_m << " rad/s, u_dc = " << u_dc << " V: " << describe(r.finding)
       << " (T_cmd = " << r.T_target << " N.m, it makes " << r.T_made << " N.m on the map); "
       << (!r.replaced          ? "no better command found: sent as is"
           : command_check == 0 ? "sent as is (command_check = 0)"
           : objective == 1 ? (table_ ? "replaced by the exact least-loss command"
                                      : "replaced by the least-loss search's command (exact in shaft torque)")
           : method == 1 && recursion == static_cast<int>(Recursion::optimal)
               ? "replaced by the robust search's command"
               : "replaced by recursion 2's checked command");
    context_->log_warning(os.str());
}

void ControllerModel::publish(const CurrentCommand& cmd, const MagnetFlux& flux, double derating_now) {
    const double sign = T_ref < 0 ? -1.0 : 1.0;
    i_d_ref = cmd.i_d;
    i_q_ref = cmd.i_q;
    T_max = sign * cmd.torque_max;
    T_cmd = sign * std::min(std::abs(T_ref), cmd.torque_max);
    if (observe_each_step) observe(flux);
    region = static_cast<int>(cmd.region);
    iterations = cmd.iterations;
    // (u_dc > 0 holds for every value the FMU accepts; the guard keeps a NaN out where it does not)
    P_loss_cmd = u_dc > 0.0 && std::isfinite(cmd.i_d) && std::isfinite(cmd.i_q)
                     ? LeastLoss::loss_at(flux, drive_loss(conditions()), motor.pole_pairs, cmd.i_d, cmd.i_q).total()
                     : 0.0;
    derating = derating_now;
    cache_ = {true, T_ref, w_m, u_dc, T_magnet, T_winding, cmd};
}

void ControllerModel::observe(const MagnetFlux& flux) {
    T_est = torque_factor(motor.pole_pairs) * flux.reduced_torque(i_d, i_q);
    u_ratio = std::hypot(u_d_ref, u_q_ref) / (u_dc / kSqrt3);
}

void ControllerModel::observe() { observe(MagnetFlux(*map_, conditions().shift)); }

void ControllerModel::initial_outputs() {
    // Outputs consistent with the initial inputs, before the first step: the current commands,
    // and the voltage that holds the measured current (a flying start: at speed, u = 0 would
    // short-circuit the machine over the first step).
    const Conditions c = conditions();
    const MagnetFlux flux(*map_, c.shift);
    cache_.valid = false;
    const CurrentCommand cmd = current_command(c);
    const FluxPoint f = flux.eval(i_d, i_q);
    double u_d = c.R * i_d - c.omega * f.psi_q, u_q = c.R * i_q + c.omega * f.psi_d;
    const double u_lim = u_dc / kSqrt3, mag = std::hypot(u_d, u_q);
    if (mag > u_lim) {
        u_d *= u_lim / mag;
        u_q *= u_lim / mag;
    }
    regulator_.state.u_d_prev = u_d_ref = u_d;
    regulator_.state.u_q_prev = u_q_ref = u_q;
    publish(cmd, flux, c.derating);
}

void ControllerModel::do_step(double /*t*/, double h) {
    const Conditions c = conditions();
    const MagnetFlux flux(*map_, c.shift);
    const CurrentCommand cmd = current_command(c);
    regulator_.set_resistance(c.R);
    const VoltageCommand u = regulator_.step(cmd.i_d, cmd.i_q, i_d, i_q, c.omega, u_dc, h, flux);
    if (!(std::isfinite(cmd.i_d) && std::isfinite(cmd.i_q) && std::isfinite(u.u_d) && std::isfinite(u.u_q)))
        throw fmi::Error("the controller produced a non-finite value (inputs out of the flux map's sensible range?)");
    if (!cmd.feasible && !warned_unreachable_ && context_->log_warning) {
        std::ostringstream os;
        os << "no current within I_max = " << motor.I_max << " A keeps the voltage within V_max = " << c.V_max
           << " V at w_m = " << w_m << " rad/s: above the maximum speed; commanding i_d = " << cmd.i_d << " A";
        context_->log_warning(os.str());
    }
    warned_unreachable_ = !cmd.feasible;
    if (regulator_.first_lowered_bandwidth(h) && context_->log_warning) {
        std::ostringstream os;
        os << "current_bandwidth = " << regulator_.bandwidth() << " rad/s is more than the communication step h = " << h
           << " s can carry (a quarter of its sampling rate, (pi/2) / h = " << regulator_.bandwidth_at(h)
           << " rad/s): the current loop runs at " << regulator_.bandwidth_at(h) << " rad/s";
        context_->log_warning(os.str());
    }
    if (regulator_.first_open_loop(u) && context_->log_warning) {
        std::ostringstream os;
        os << "the communication step h = " << h << " s is too long for the current loop at w_m = " << w_m
           << " rad/s: the rotor turns by " << std::abs(c.omega * h) << " rad (electrical) within one step, and from "
           << kMaxRotationPerSample << " rad a dq voltage held over the step averages out and cannot steer the "
           << "flux; u_d_ref, u_q_ref are the current commands' steady-state voltage, open loop, while this holds "
           << "(use a step below " << kMaxRotationPerSample / std::abs(c.omega) << " s at this speed)";
        context_->log_warning(os.str());
    }
    u_d_ref = u.u_d;
    u_q_ref = u.u_q;
    voltage_saturated = u.limited;
    publish(cmd, flux, c.derating);
}

}  // namespace ipmsm
