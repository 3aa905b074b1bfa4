#include "plant_model.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <deque>
#include <limits>
#include <mutex>
#include <sstream>
#include <utility>

#include "machine/machine.hpp"
#include "machine/magnet_flux.hpp"
#include "machine/map_file.hpp"
#include "machine/operating_region.hpp"
#include "parts/motor_map.hpp"
#include "parts/part_variables.hpp"

namespace ipmsm {

using fmi::Causality;
using fmi::Variability;
using V = fmi::Variable<PlantModel>;
using M = PlantModel;

namespace {
constexpr double kInf = std::numeric_limits<double>::infinity();
// The most internal steps one fmi2DoStep may take (cvode_max_steps' maximum): one step cannot be
// interrupted, so its work is bounded: 2e5 steps of a few microseconds (docs/spec/INTERFACE.md,
// "Bounded steps"), 10 times the default. A step needing more is a stiff map for BDF
// (cvode_method 2) or a communication step to cut, not a reason to compute for minutes.
constexpr int kMaxCvodeSteps = 200000;
constexpr double kVoltageMax = 1e4;  // V: far beyond any traction inverter
constexpr double kSpeedMax = 1e4;    // rad/s mechanical (95 000 r/min)
// Explicit steps per call before CVODE in ASC (settings()): the short circuit's ringing takes
// 5-15 a call from 3000 to 12000 r/min on the default motor, a few calls of a trip more.
constexpr int kAscExplicitAttempts = 32;

std::string num(double x) {
    std::ostringstream os;
    os.precision(10);
    os << x;
    return os.str();
}

// The inverse of a map on its legal box, built once per map and box (the maps are shared by
// content, flux_map_cache.hpp): Initialization Mode's previews and a second instance do not build
// it again. Bounded like the map cache; thread-safe.
std::shared_ptr<const InverseFluxMap> shared_inverse(const std::shared_ptr<const FluxMap>& map,
                                                     const CurrentBox& legal) {
    struct Entry {
        std::shared_ptr<const FluxMap> map;
        CurrentBox legal;
        std::shared_ptr<const InverseFluxMap> inverse;
    };
    static std::mutex mutex;
    static std::deque<Entry> cache;
    auto same = [&](const CurrentBox& b) {
        return b.i_d_min == legal.i_d_min && b.i_d_max == legal.i_d_max && b.i_q_min == legal.i_q_min &&
               b.i_q_max == legal.i_q_max;
    };
    {
        std::lock_guard<std::mutex> lock(mutex);
        for (const auto& e : cache)
            if (e.map == map && same(e.legal)) return e.inverse;
    }
    InverseFluxMapOptions options;
    options.legal = legal;
    auto inverse = std::make_shared<const InverseFluxMap>(*map, options);  // outside the lock: milliseconds
    std::lock_guard<std::mutex> lock(mutex);
    cache.push_front(Entry{map, legal, inverse});
    if (cache.size() > 4) cache.pop_back();
    return inverse;
}
}  // namespace

const std::vector<V>& PlantModel::variables() {
    const auto motor = [](const char* name) { return fmi::part_variable(&M::motor, name); };
    static const std::vector<V> table = [&] {
        std::vector<V> t = fmi::join<M>({
            {
                // inputs
                {"u_d", &M::u_d, Causality::input, Variability::continuous, "V", "",
                 "d-axis stator voltage (average inverter output, peak, amplitude-invariant), held over each step",
                 -kVoltageMax, kVoltageMax},
                {"u_q", &M::u_q, Causality::input, Variability::continuous, "V", "",
                 "q-axis stator voltage (average inverter output, peak, amplitude-invariant), held over each step",
                 -kVoltageMax, kVoltageMax},
                {"w_m", &M::w_m, Causality::input, Variability::continuous, "rad/s", "rpm",
                 "Mechanical rotor speed, set by the vehicle side (either sign)", -kSpeedMax, kSpeedMax},
                {"T_magnet", &M::T_magnet, Causality::input, Variability::continuous, "K", "degC",
                 "Magnet temperature: the PM flux is psi_m (1 + k_psi_T (T_magnet - T_magnet_ref))", kTemperatureMin_K,
                 kTemperatureMax_K},
                {"T_winding", &M::T_winding, Causality::input, Variability::continuous, "K", "degC",
                 "Winding temperature: R = R_s (1 + alpha_cu (T_winding - T_winding_ref))", kTemperatureMin_K,
                 kTemperatureMax_K},
                // outputs
                {"i_d", &M::i_d, Causality::output, Variability::continuous, "A", "",
                 "d-axis stator current (peak, amplitude-invariant), from the inverse flux map"},
                {"i_q", &M::i_q, Causality::output, Variability::continuous, "A", "",
                 "q-axis stator current (peak, amplitude-invariant), from the inverse flux map"},
                {"psi_d", &M::psi_d, Causality::output, Variability::continuous, "Wb", "",
                 "d-axis flux linkage (integrated state)"},
                {"psi_q", &M::psi_q, Causality::output, Variability::continuous, "Wb", "",
                 "q-axis flux linkage (integrated state)"},
                {"T_e", &M::T_e, Causality::output, Variability::continuous, "N.m", "",
                 "Electromagnetic torque 1.5 p (psi_d i_q - psi_q i_d)"},
                {"T_shaft", &M::T_shaft, Causality::output, Variability::continuous, "N.m", "",
                 "Shaft torque: T_e less the iron-loss drag P_fe / w_m"},
                {"P_elec", &M::P_elec, Causality::output, Variability::continuous, "W", "",
                 "Electrical input power 1.5 (u_d i_d + u_q i_q)"},
                {"P_mech", &M::P_mech, Causality::output, Variability::continuous, "W", "",
                 "Shaft power T_shaft w_m (= T_e w_m - P_fe)"},
                {"P_cu", &M::P_cu, Causality::output, Variability::continuous, "W", "",
                 "Copper loss 1.5 R (i_d^2 + i_q^2) at the winding temperature"},
                {"P_fe", &M::P_fe, Causality::output, Variability::continuous, "W", "",
                 "Iron loss fe_k_h f b^fe_alpha + fe_k_e f^2 b^2, f = p |w_m| / (2 pi), b = |psi| / fe_psi_ref"},
                {"psi_m_T", &M::psi_m_T, Causality::output, Variability::continuous, "Wb", "",
                 "PM flux linkage at the magnet temperature (the map's psi_d(0, 0) shifted)"},
                {"R_s_T", &M::R_s_T, Causality::output, Variability::continuous, "Ohm", "",
                 "Stator resistance at the winding temperature"},
                {"E_elec", &M::E_elec, Causality::output, Variability::continuous, "J", "Wh",
                 "Electrical input energy since the start, int P_elec dt (exact over each step: a CVODE quadrature "
                 "under error control)"},
                {"E_mech", &M::E_mech, Causality::output, Variability::continuous, "J", "Wh",
                 "Shaft energy since the start, int P_mech dt = w_m int T_e dt - int P_fe dt over each step (w_m "
                 "held)"},
                {"E_cu", &M::E_cu, Causality::output, Variability::continuous, "J", "Wh",
                 "Copper-loss energy since the start, int P_cu dt"},
                {"E_fe", &M::E_fe, Causality::output, Variability::continuous, "J", "Wh",
                 "Iron-loss energy since the start, int P_fe dt"},
                {"T_e_impulse", &M::T_e_impulse, Causality::output, Variability::continuous, "N.m.s", "",
                 "Angular impulse of the electromagnetic torque since the start, int T_e dt (its mean over a step is "
                 "the increase over the step divided by the step)"},
                {"cvode_steps", &M::cvode_steps, Causality::output, Variability::discrete, "", "",
                 "Internal steps of the integrator in the last communication step (CVODE's, or the explicit "
                 "Runge-Kutta steps that met the tolerances)"},
                {"cvode_rhs_evals", &M::cvode_rhs_evals, Causality::output, Variability::discrete, "", "",
                 "Right-hand-side evaluations in the last communication step"},
                // parameters
                motor("flux_map"),
                motor("pole_pairs"),
                motor("R_s"),
                motor("T_winding_ref"),
                motor("alpha_cu"),
                motor("k_psi_T"),
                motor("T_magnet_ref"),
            },
            fmi::part_variables(&M::iron_loss),
            {
                {"i_d_start", &M::i_d_start, Causality::parameter, Variability::fixed, "A", "",
                 "Initial d-axis current (the initial fluxes are the map's at the initial currents)", -1e5, 1e5},
                {"i_q_start", &M::i_q_start, Causality::parameter, Variability::fixed, "A", "",
                 "Initial q-axis current", -1e5, 1e5},
                {"rtol", &M::rtol, Causality::parameter, Variability::tunable, "1", "", "CVODE relative tolerance",
                 1e-14, 0.1},
                {"atol", &M::atol, Causality::parameter, Variability::tunable, "Wb", "",
                 "CVODE absolute tolerance on the flux linkages (the local error per internal step, Wb)", 1e-15, 1.0},
                {"cvode_method", &M::cvode_method, Causality::parameter, Variability::fixed, "", "",
                 "1 Adams-Moulton with functional iteration (non-stiff; default), 2 BDF with Newton and the analytic "
                 "Jacobian (stiff maps)",
                 1, 2},
                {"cvode_max_order", &M::cvode_max_order, Causality::parameter, Variability::fixed, "", "",
                 "Largest order CVODE may use; 0: the method's maximum (Adams 12, BDF 5)", 0, 12},
                {"cvode_max_steps", &M::cvode_max_steps, Causality::parameter, Variability::tunable, "", "",
                 "Internal steps allowed per communication step before CVODE fails", 1, kMaxCvodeSteps},
                // I_max (0.2.0) here: 0.1.0's value references above stay theirs, and 0.2.0's thermal
                // ones below stay theirs (0.2.0 had it before i_d_start; CHANGELOG)
                motor("I_max"),
                // the thermal network (docs/thermal.md), added in 0.2.0: after the variables of 0.1.0
                {"T_coolant", &M::T_coolant, Causality::input, Variability::continuous, "K", "degC",
                 "Coolant temperature the thermal network rejects heat to (thermal_model; held over each step)",
                 kTemperatureMin_K, kTemperatureMax_K},
                {"T_ambient", &M::T_ambient, Causality::input, Variability::continuous, "K", "degC",
                 "Ambient-air temperature the thermal network's rotor also rejects heat to (thermal_model)",
                 kTemperatureMin_K, kTemperatureMax_K},
                {"theta_winding", &M::theta_winding, Causality::output, Variability::continuous, "K", "degC",
                 "Winding temperature: the thermal network's winding node (thermal_model), else the T_winding input"},
                {"theta_magnet", &M::theta_magnet, Causality::output, Variability::continuous, "K", "degC",
                 "Magnet temperature: the thermal network's magnet (rotor) node (thermal_model), else the T_magnet "
                 "input"},
                {"theta_stator_yoke", &M::theta_stator_yoke, Causality::output, Variability::continuous, "K", "degC",
                 "Stator-yoke temperature: the thermal network's node (thermal_model), else the T_winding input"},
                {"theta_stator_tooth", &M::theta_stator_tooth, Causality::output, Variability::continuous, "K", "degC",
                 "Stator-tooth temperature: the thermal network's node (thermal_model), else the T_winding input"},
                {"P_coolant", &M::P_coolant, Causality::output, Variability::continuous, "W", "",
                 "Heat into the coolant, mean over the last step (thermal_model; else 0)"},
                {"E_coolant", &M::E_coolant, Causality::output, Variability::continuous, "J", "Wh",
                 "Heat into the coolant since the start (thermal_model; else 0)"},
                {"E_ambient", &M::E_ambient, Causality::output, Variability::continuous, "J", "Wh",
                 "Heat into the ambient air since the start (thermal_model; else 0)"},
                {"E_stored", &M::E_stored, Causality::output, Variability::continuous, "J", "Wh",
                 "Heat stored in the thermal network since the start, sum C_i (theta_i - theta_i(0)): E_cu + E_fe = "
                 "E_stored + E_coolant + E_ambient (thermal_model; else 0)"},
                {"thermal_model", &M::thermal_model, Causality::parameter, Variability::fixed, "", "",
                 "true: a thermal network of the machine (docs/thermal.md) sets the winding and magnet temperatures "
                 "from the losses, T_coolant and T_ambient, and the T_winding, T_magnet inputs only start it; false: "
                 "they are the inputs"},
            },
            fmi::part_variables(&M::lptn),
            {
                // the inverter feeding the machine (inverter/inverter_loss.hpp), new after 0.2.0: last, so
                // that every earlier value reference stays
                {"u_dc", &M::u_dc, Causality::input, Variability::continuous, "V", "",
                 "DC-link voltage the inverter switches (its loss P_inv), held over each step", 0.0, kInf, true},
                {"P_inv", &M::P_inv, Causality::output, Variability::continuous, "W", "",
                 "Inverter conduction and switching loss over the last step: the current sampled at its end, the "
                 "step's mean AC power (E_elec's increase over the step), u_dc held"},
                {"E_inv", &M::E_inv, Causality::output, Variability::continuous, "J", "Wh",
                 "Inverter-loss energy since the start, P_inv h summed over the steps"},
            },
            fmi::part_variables(&M::inverter),
            {
                // the inverter's safe states (docs/spec/INTERFACE.md, "Faults"; docs/faults.md): appended
                {"inverter_state", &M::inverter_state, Causality::input, Variability::discrete, "", "",
                 "What the inverter does: 0 switching (u_d, u_q applied), 1 freewheeling (all gates off: the diode "
                 "bridge "
                 "rectifies into u_dc once the back-EMF can drive a current into it), 2 active short circuit (u_d = "
                 "u_q = 0); "
                 "changeable at any communication point",
                 0.0, 2.0},
                {"i_d_demag", &M::i_d_demag, Causality::parameter, Variability::fixed, "A", "",
                 "The magnets' demagnetisation limit on i_d (negative; 0: none): a warning, once, when i_d passes it",
                 -1e6, 0.0},
                {"i_dc", &M::i_dc, Causality::output, Variability::continuous, "A", "",
                 "DC-link current of the inverter over the last step, losses included (+ motoring): (E_elec's increase "
                 "+ "
                 "P_inv h) / (u_dc h); freewheeling, -(3/pi) |i| and the diodes' loss; ASC: 0"},
                {"bridge_switchings", &M::bridge_switchings, Causality::output, Variability::discrete, "", "",
                 "Freewheeling: the diode bridge's switchings between conducting and blocking since the start"},
            },
        });
        fmi::append_rest(t, &M::motor);
        fmi::append_rest(t, &M::iron_loss);
        fmi::append_rest(t, &M::lptn);
        fmi::append_rest(t, &M::inverter);
        return t;
    }();
    return table;
}

PlantModel::PlantModel(const fmi::Context& context) : context_(fmi::share(context)), integrator_(settings()) {}

CvodeSettings PlantModel::settings() const {
    CvodeSettings s;
    s.method = cvode_method == 2 ? CvodeMethod::bdf : CvodeMethod::adams;
    s.nonlinear = cvode_method == 2 ? CvodeNonlinear::newton_analytic : CvodeNonlinear::fixed_point;
    s.max_order = cvode_max_order;
    s.max_steps = cvode_max_steps;
    s.rtol = rtol;
    s.atol = atol;
    s.linearised = true;  // the step's linear flow exact, CVODE on the rest (ibid.)
    s.init_step = CvodeInitStep::curvature;
    s.nonlin_conv_coef = 0.3;  // measured: 15-25 % fewer RHS evaluations, same error (bench_plant)
    s.explicit_first = true;   // CVODE only where the embedded Runge-Kutta steps give up (cvode_integrator.hpp)
    if (map_)                  // the quadratures' absolute tolerances scale with the largest current of the map's grid
        s.current_scale = std::max({std::abs(map_->i_d_min()), std::abs(map_->i_d_max()), std::abs(map_->i_q_min()),
                                    std::abs(map_->i_q_max())});
    // The short circuit's transient rings at omega in dq until it decays over L/R (tenths of a
    // second at the default motor's milliohms), and the step integrals (T_e, P_cu) must follow the
    // ringing to rtol: ~5-15 explicit steps a call, each a few right-hand sides, where CVODE,
    // restarted at order 1 in every call, takes as many steps at several times their cost
    // (docs/performance.md, "The inverter's safe states"). Switching keeps the general bound.
    if (inverter_state == static_cast<int>(InverterState::asc)) s.explicit_attempts = kAscExplicitAttempts;
    return s;
}

StepIntegrands PlantModel::integrands() const { return StepIntegrands{motor.pole_pairs, w_m, iron_loss}; }

void PlantModel::exit_initialization() {
    // Everything into locals first: a throw leaves the model as it was.
    const fmi::Context& ctx = *context_;
    const std::string path = flux_map_path(motor, ctx);
    if (cvode_method == 2 && cvode_max_order > 5)
        throw fmi::Error("cvode_max_order = " + std::to_string(cvode_max_order) +
                         ": BDF (cvode_method 2) has orders 1 to 5");
    if (const std::string e = winding_law_error(motor.alpha_cu, motor.T_winding_ref); !e.empty()) throw fmi::Error(e);

    const auto t0 = std::chrono::steady_clock::now();
    const MotorMap loaded =
        load_motor_map(motor, path, ctx, [this](const std::string& p) { return fmi::parameter_number(*this, p); });
    std::shared_ptr<const FluxMap> map = loaded.map;
    std::shared_ptr<const InverseFluxMap> inverse;
    try {
        inverse = shared_inverse(map, loaded.acceptance.legal);  // inverted where legal, continued beyond
    } catch (const std::exception& e) {
        throw fmi::Error(std::string("flux map: ") + e.what());
    }
    const double build_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    const FluxMapTable& t = map->table();

    // Initial state: the fluxes at the initial currents and the present magnet temperature.
    // Currents outside the grid would start the machine on the map's extrapolation: refused.
    auto inside = [](double x, double lo, double hi) { return x >= lo && x <= hi; };
    if (!inside(i_d_start, map->i_d_min(), map->i_d_max()) || !inside(i_q_start, map->i_q_min(), map->i_q_max()))
        throw fmi::Error("the start currents i_d_start = " + num(i_d_start) + " A, i_q_start = " + num(i_q_start) +
                         " A are outside the flux map's grid [" + num(map->i_d_min()) + ", " + num(map->i_d_max()) +
                         "] x [" + num(map->i_q_min()) + ", " + num(map->i_q_max()) + "] A (" + path + ")");
    const double shift = magnet_flux_shift(*map, motor.k_psi_T, T_magnet, motor.T_magnet_ref);
    const FluxPoint p0 = inverse->forward_eval(i_d_start, i_q_start);  // the map the plant inverts
    std::optional<thermal::MotorThermal> network;
    if (thermal_model) {  // the stator nodes start at the winding's temperature, the rotor at the magnets'
        thermal::NodeVector theta0;
        theta0 << T_winding, T_winding, T_winding, T_magnet;
        try {
            network.emplace(lptn, theta0);
        } catch (const std::invalid_argument& e) {
            throw fmi::Error(e.what());
        }
    }
    CvodeIntegrator integrator(settings());
    integrator.reset(0.0, p0.psi_d + shift, p0.psi_q);
    CvodeState start = integrator.state();  // the start currents: exactly those at the start fluxes
    start.i_seed[0] = i_d_start;
    start.i_seed[1] = i_q_start;
    integrator.set_state(start);

    // Commit.
    map_ = std::move(map);
    inverse_ = std::move(inverse);
    integrator_ = std::move(integrator);
    thermal_ = std::move(network);
    outside_warned_ = false;
    E_elec = E_mech = E_cu = E_fe = T_e_impulse = 0.0;
    cvode_steps = 0;
    cvode_rhs_evals = 0;
    // The fluxes are the map's at the start currents, so those are exactly the currents there
    // (the inverse map would return them to its rounding, not bit for bit).
    blocked_ = false;
    demag_warned_ = false;
    bridge_switchings = 0;
    update_outputs(terminal_voltage(ode(), i_d_start, i_q_start), i_d_start, i_q_start);
    update_thermal_outputs();
    E_inv = 0.0;
    // at the start: the start current and the power the inputs make
    const double I2 = i_d * i_d + i_q * i_q;
    P_inv = inverter_loss_in_state(P_elec, std::sqrt(I2), I2);
    i_dc = (P_elec + P_inv) / u_dc;

    if (ctx.log_info) {
        std::ostringstream os;
        os << "flux map " << quoted_excerpt(path) << ": " << t.i_d.size() << " x " << t.i_q.size()
           << " points, psi_m = " << num(map_->psi_m()) << " Wb; inverse map " << inverse_->n_psi_d() << " x "
           << inverse_->n_psi_q() << " (max residual " << inverse_->max_residual() << " Wb, "
           << inverse_->outside_nodes() << " nodes on the extrapolated map) built in " << num(build_ms) << " ms; CVODE "
           << (cvode_method == 2 ? "BDF/Newton" : "Adams/functional iteration") << ", rtol " << num(rtol) << ", atol "
           << num(atol) << " Wb";
        ctx.log_info(os.str());
    }
}

DqFluxOde PlantModel::ode() const {
    if (!inverse_) throw fmi::Error("the flux map is not loaded (the model is not initialised)");
    DqFluxOde o;
    o.inverse = inverse_.get();
    o.u_d = u_d;
    o.u_q = u_q;
    o.omega = motor.pole_pairs * w_m;
    const double T_w = winding_temperature(), T_m = magnet_temperature();
    o.R = motor.resistance(T_w);
    o.delta_psi_m = magnet_flux_shift(*map_, motor.k_psi_T, T_m, motor.T_magnet_ref);
    if (!(o.R >= 0.0))
        throw fmi::Error("the stator resistance at T_winding = " + num(T_w) + " K is " + num(o.R) +
                         " Ohm (R_s = " + num(motor.R_s) + " Ohm, alpha_cu = " + num(motor.alpha_cu) + " 1/K)");
    return o;
}

void PlantModel::update_outputs(const DqFluxOde& o) {
    const CvodeState& s = integrator_.state();
    const InverseFluxPoint c = o.currents(s.psi[0], s.psi[1]);
    update_outputs(o, c.i_d, c.i_q);
}

void PlantModel::update_outputs(const DqFluxOde& o, double i_d_now, double i_q_now) {
    const CvodeState& s = integrator_.state();
    const PlantOutputs out =
        plant_outputs(o, motor.pole_pairs, w_m, integrands().fe, s.psi[0], s.psi[1], i_d_now, i_q_now);
    psi_d = s.psi[0];
    psi_q = s.psi[1];
    i_d = out.i_d;
    i_q = out.i_q;
    T_e = out.T_e;
    T_shaft = out.T_shaft;
    P_elec = out.P_elec;
    P_mech = out.P_mech;
    P_cu = out.P_cu;
    P_fe = out.P_fe;
    psi_m_T = map_->psi_m() + o.delta_psi_m;
    R_s_T = o.R;
}

// A Newton seed this many times the grid's largest current from the origin is no start the
// inverse map's Newton needs: the table's start is nearer.
constexpr double kSeedReach = 10.0;

PlantModel::StateRanges PlantModel::state_ranges() const {
    StateRanges r{{"a flux linkage of the plant's state (Wb)", -kInf, kInf},
                  {"a current of the plant's state (A)", -kInf, kInf},
                  {"the plant's next step size (s)", 0.0, kInf},
                  {"a thermal-network node temperature (K)", kTemperatureMin_K, kTemperatureMax_K}};
    if (map_) {  // before initialisation there is no map, and no state but the start values
        const MapSpan span = map_span(map_->table());
        const double psi = flux_reach(span, map_->psi_m(), motor.k_psi_T);
        const double i = kSeedReach * std::max({std::abs(span.i_d[0]), std::abs(span.i_d[1]), std::abs(span.i_q[0]),
                                                std::abs(span.i_q[1])});
        r.flux.min = -psi, r.flux.max = psi;
        r.current.min = -i, r.current.max = i;
    }
    return r;
}

void PlantModel::check_thermal_state() const {
    if (!thermal_) return;
    // (Not its heat balance: steps the plant takes legally leave it open by more than rounding
    // (5.6e-6 of the largest energy after hostile steps); a state the instance is in must serialise.)
    const bool same =
        theta_winding == thermal_->theta(thermal::winding) && theta_magnet == thermal_->theta(thermal::magnet) &&
        theta_stator_yoke == thermal_->theta(thermal::stator_yoke) &&
        theta_stator_tooth == thermal_->theta(thermal::stator_tooth) && E_coolant == thermal_->E_coolant() &&
        E_ambient == thermal_->E_ambient() && E_stored == thermal_->E_stored() && P_coolant == thermal_->P_coolant();
    if (!same)
        throw fmi::Error(
            "serialised FMU state: the thermal outputs (theta_*, E_coolant, E_ambient, E_stored, P_coolant) are not "
            "the thermal network's state; not restored");
}

void PlantModel::advance_thermal(double h, double E_cu_step, double E_fe_step) {
    if (thermal_ && h > 0.0) {  // the step's exact loss integrals heat the network
        thermal::StepConditions at;
        at.w_m = w_m;
        at.I_rms = std::sqrt(0.5 * (i_d * i_d + i_q * i_q));  // peak amplitude-invariant -> RMS
        at.T_coolant = T_coolant;
        at.T_ambient = T_ambient;
        try {
            thermal_->advance(h, E_cu_step, E_fe_step, at);
        } catch (const std::invalid_argument& e) {
            throw fmi::Error(e.what());
        }
    }
    update_thermal_outputs();
}

DqFluxOde PlantModel::terminal_voltage(DqFluxOde o, double i_d_now, double i_q_now) const {
    switch (static_cast<InverterState>(inverter_state)) {
        case InverterState::switching: break;
        case InverterState::asc: o.u_d = o.u_q = 0.0; break;
        case InverterState::freewheeling: {
            const double r = std::hypot(i_d_now, i_q_now), k = bridge_amplitude(u_dc);
            o.u_d = r > 0.0 ? -k * i_d_now / r : 0.0;  // blocked (i = 0): no current, no power
            o.u_q = r > 0.0 ? -k * i_q_now / r : 0.0;
            break;
        }
    }
    return o;
}

double PlantModel::inverter_loss_in_state(double P_ac, double I, double I2) const {
    switch (static_cast<InverterState>(inverter_state)) {
        case InverterState::switching: return inverter_loss_now(P_ac);
        case InverterState::freewheeling: return diode_bridge_loss(inverter.V_D0, inverter.r_D, I, I2);
        case InverterState::asc: break;
    }
    return 0.0;  // the ideal short: no voltage across the switches, no loss (docs/faults.md)
}

double PlantModel::inverter_loss_now(double P_ac) const {
    const double I2 = i_d * i_d + i_q * i_q;
    try {
        return InverterLossModel(inverter, u_dc).at(std::sqrt(I2), I2, P_ac).P();
    } catch (const std::invalid_argument& e) {
        throw fmi::Error(e.what());
    }
}

void PlantModel::update_thermal_outputs() {
    if (thermal_) {
        theta_winding = thermal_->theta(thermal::winding);
        theta_magnet = thermal_->theta(thermal::magnet);
        theta_stator_yoke = thermal_->theta(thermal::stator_yoke);
        theta_stator_tooth = thermal_->theta(thermal::stator_tooth);
        P_coolant = thermal_->P_coolant();
        E_coolant = thermal_->E_coolant();
        E_ambient = thermal_->E_ambient();
        E_stored = thermal_->E_stored();
    } else {
        theta_winding = theta_stator_yoke = theta_stator_tooth = T_winding;
        theta_magnet = T_magnet;
        P_coolant = E_coolant = E_ambient = E_stored = 0.0;
    }
}

void PlantModel::do_step(double t, double h) {
    const auto state = static_cast<InverterState>(inverter_state);
    DqFluxOde o = ode();
    if (state == InverterState::asc) o.u_d = o.u_q = 0.0;
    if (state != InverterState::freewheeling) blocked_ = false;
    integrator_.set_settings(settings());  // rtol, atol, cvode_max_steps are tunable
    CvodeState start = integrator_.state();
    start.t = t;  // bookkeeping: the integration runs in time relative to t (cvode_integrator.hpp)
    integrator_.set_state(start);
    const double E_elec_before = E_elec;
    try {
        if (state == InverterState::freewheeling) {
            freewheel_step(o, h);
        } else {
            const StepIntegrands q = integrands();
            integrator_.advance(o, h, &q);
            const CvodeState& end = integrator_.state();
            const InverseFluxPoint& c = integrator_.end_currents();
            if (!std::isfinite(c.i_d) || !std::isfinite(c.i_q))
                throw CvodeError(
                    "no current on the flux map or its linear continuation gives the flux linkages psi_d = " +
                    num(end.psi[0]) + " Wb, psi_q = " + num(end.psi[1]) + " Wb reached at the end of the step");
            update_outputs(o, c.i_d, c.i_q);
            const double* e = integrator_.step_integrals();
            E_elec += e[StepIntegrands::P_elec];
            // the step's mean AC power as the increase of E_elec (what a master holding E_elec sees)
            P_inv = state == InverterState::asc ? 0.0 : inverter_loss_now((E_elec - E_elec_before) / h);
            E_inv += P_inv * h;
            E_cu += e[StepIntegrands::P_cu];
            E_fe += e[StepIntegrands::P_fe];
            E_mech += w_m * e[StepIntegrands::T_e] - e[StepIntegrands::P_fe];
            T_e_impulse += e[StepIntegrands::T_e];
            if (thermal_each_step) advance_thermal(h, e[StepIntegrands::P_cu], e[StepIntegrands::P_fe]);
            const CvodeStats& st = integrator_.stats();
            cvode_steps = static_cast<int>(st.steps);
            cvode_rhs_evals = static_cast<int>(st.rhs_evals);
        }
    } catch (const std::exception& e) {
        std::ostringstream os;
        os << e.what() << " [inputs u_d = " << num(u_d) << " V, u_q = " << num(u_q) << " V, w_m = " << num(w_m)
           << " rad/s, inverter_state " << inverter_state << "; state psi_d = " << num(start.psi[0])
           << " Wb, psi_q = " << num(start.psi[1]) << " Wb; rtol " << num(rtol) << ", atol " << num(atol)
           << ", cvode_max_steps " << cvode_max_steps << "]";
        throw fmi::Error(os.str());
    }
    i_dc = (E_elec - E_elec_before + P_inv * h) / (u_dc * h);

    const fmi::Context& ctx = *context_;
    if (!integrator_.warnings().empty() && ctx.log_warning)
        ctx.log_warning("CVODE at t = " + num(t) + " s: " + integrator_.warnings());
    const CurrentBox& legal = inverse_->legal();
    const bool outside = !legal.contains(i_d, i_q);
    if (outside && !outside_warned_ && ctx.log_warning) {
        std::ostringstream os;
        os << "at t = " << num(t + h) << " s the currents i_d = " << num(i_d) << " A, i_q = " << num(i_q)
           << " A left the flux map's legal box (" << describe(legal)
           << "): the plant continues the map there with positive-definite incremental inductances (docs/maps.md; "
              "warned once per excursion)";
        ctx.log_warning(os.str());
    }
    outside_warned_ = outside;
    warn_demagnetising(t + h);
}

double PlantModel::back_emf_line_peak() const {
    const FluxPoint z = inverse_->forward_eval(0.0, 0.0);
    const double psi0_d = z.psi_d + magnet_flux_shift(*map_, motor.k_psi_T, magnet_temperature(), motor.T_magnet_ref);
    return std::sqrt(3.0) * std::abs(motor.pole_pairs * w_m) * std::hypot(psi0_d, z.psi_q);
}

void PlantModel::warn_demagnetising(double t_now) {
    if (demag_warned_ || !(i_d_demag < 0.0) || !(i_d < i_d_demag)) return;
    demag_warned_ = true;
    const fmi::Context& ctx = *context_;
    if (ctx.log_warning)
        ctx.log_warning("at t = " + num(t_now) + " s i_d = " + num(i_d) +
                        " A passed the magnets' demagnetisation limit " + "i_d_demag = " + num(i_d_demag) +
                        " A (inverter_state " + std::to_string(inverter_state) + "; warned once)");
}

void PlantModel::freewheel_step(const DqFluxOde& o, double h) {
    const StepIntegrands q = integrands();
    CvodeState s = integrator_.state();
    // a step entering freewheeling without current starts blocked (psi is psi_0 there)
    const bool blocked = blocked_ || (i_d == 0.0 && i_q == 0.0);
    const FreewheelStep r =
        freewheel_.advance(o, bridge_amplitude(u_dc), q, settings(), h, s.psi, blocked, s.i_seed, s.h_next);
    s.t += h;
    s.psi[0] = r.psi[0];
    s.psi[1] = r.psi[1];
    s.i_seed[0] = r.c.i_d;
    s.i_seed[1] = r.c.i_q;
    s.h_next = r.h_last;
    integrator_.set_state(s);
    blocked_ = r.blocked;
    bridge_switchings += r.switchings;
    update_outputs(terminal_voltage(o, r.c.i_d, r.c.i_q), r.c.i_d, r.c.i_q);
    const double* e = r.integrals;
    E_elec += e[StepIntegrands::P_elec];
    P_inv = diode_bridge_loss(inverter.V_D0, inverter.r_D, r.I_integral / h, r.I2_integral / h);  // exact means
    E_inv += P_inv * h;
    E_cu += e[StepIntegrands::P_cu];
    E_fe += e[StepIntegrands::P_fe];
    E_mech += w_m * e[StepIntegrands::T_e] - e[StepIntegrands::P_fe];
    T_e_impulse += e[StepIntegrands::T_e];
    if (thermal_each_step) advance_thermal(h, e[StepIntegrands::P_cu], e[StepIntegrands::P_fe]);
    cvode_steps = static_cast<int>(r.steps);
    cvode_rhs_evals = static_cast<int>(r.rhs_evals);
}

}  // namespace ipmsm
