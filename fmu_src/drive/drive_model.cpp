#include "drive/drive_model.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <set>
#include <sstream>
#include <utility>

#include "coupling/drive_coupling_text.hpp"
#include "fmi2_support.hpp"
#include "parts/part_variables.hpp"

namespace ipmsm {

using fmi::Causality;
using fmi::Variability;
using V = fmi::Variable<DriveModel>;
using M = DriveModel;

namespace {

const coupling::Coupling& drive_coupling() {
    static const coupling::Coupling c = coupling::parse(coupling::kDriveCouplingText);
    return c;
}

// The drive's entry for a variable of the plant and/or the controller: the plant's unit,
// description and causality (the controller's where the plant has none), the range both accept,
// fixed where either is fixed. One source: the models' tables.
V of_models(const char* name, fmi::Member<M> member) {
    const auto* p = fmi::find_variable<PlantModel>(name);
    const auto* c = fmi::find_variable<ControllerModel>(name);
    if (p == nullptr && c == nullptr) throw std::logic_error(std::string("IpmsmDrive: no model has ") + name);
    V v = p != nullptr ? V{p->name, std::move(member), p->causality,         p->variability,
                           p->unit, p->display_unit,   p->description,       p->min,
                           p->max,  p->min_exclusive,  p->relative_quantity, p->dimensions}
                       : V{c->name, std::move(member), c->causality,         c->variability,
                           c->unit, c->display_unit,   c->description,       c->min,
                           c->max,  c->min_exclusive,  c->relative_quantity, c->dimensions};
    if (p != nullptr && c != nullptr) {
        if (p->member.index() != c->member.index())
            throw std::logic_error(std::string("IpmsmDrive: the models' ") + name + " differ in type");
        v.min_exclusive = (c->min > p->min)
                              ? c->min_exclusive
                              : (p->min > c->min ? p->min_exclusive : (p->min_exclusive || c->min_exclusive));
        v.min = std::max(p->min, c->min);
        v.max = std::min(p->max, c->max);
        if (c->variability == Variability::fixed) v.variability = Variability::fixed;
    }
    return v;
}

// How a model reaches a variable of type T (empty: it has none); a member or a forwarded one.
template <class T, class Sub>
std::optional<fmi::Access<Sub, T>> access_of(const fmi::Variable<Sub>* v) {
    if (v == nullptr) return std::nullopt;
    return std::get<fmi::Access<Sub, T>>(v->member);
}

// A parameter the drive forwards to the models that have it: read from the plant where it has
// one (else from the controller), written to both.
template <class T>
fmi::Member<M> to_models(const char* name, ControllerModel M::*controller, PlantModel M::*plant) {
    const auto c = access_of<T>(fmi::find_variable<ControllerModel>(name));
    const auto p = access_of<T>(fmi::find_variable<PlantModel>(name));
    return fmi::Access<M, T>{[=](const M& d) { return p ? p->read(d.*plant) : c->read(d.*controller); },
                             [=](M& d, const T& x) {
                                 if (c) c->write(d.*controller, x);
                                 if (p) p->write(d.*plant, x);
                             }};
}

// A parameter of the models, declared once: of_models() with the value forwarded to them.
V parameter(const char* name, ControllerModel M::*controller, PlantModel M::*plant) {
    const auto* p = fmi::find_variable<PlantModel>(name);
    const auto* c = fmi::find_variable<ControllerModel>(name);
    const fmi::Type t = p != nullptr ? fmi::type_of(*p) : c != nullptr ? fmi::type_of(*c) : fmi::Type::Real;
    switch (t) {
        case fmi::Type::Real: return of_models(name, to_models<double>(name, controller, plant));
        case fmi::Type::Integer: return of_models(name, to_models<int>(name, controller, plant));
        case fmi::Type::Boolean: return of_models(name, to_models<bool>(name, controller, plant));
        case fmi::Type::String: return of_models(name, to_models<std::string>(name, controller, plant));
        case fmi::Type::UInt64: return of_models(name, to_models<std::uint64_t>(name, controller, plant));
        case fmi::Type::RealArray: return of_models(name, to_models<std::vector<double>>(name, controller, plant));
    }
    throw std::logic_error(std::string("IpmsmDrive: ") + name + " has no FMI type");
}

constexpr double kInf = std::numeric_limits<double>::infinity();

// The drive's table as it is built (value reference = row): its own variables, the models'
// outputs it reads at the end of a step, and the models' parameters, forwarded; each name once.
class Table {
public:
    Table(ControllerModel M::*controller, PlantModel M::*plant) : controller_(controller), plant_(plant) {}

    void add(V v) {
        if (!names_.insert(v.name).second) throw std::logic_error(std::string("IpmsmDrive: ") + v.name + " twice");
        rows.push_back(std::move(v));
    }
    void add_all(std::vector<V> vs) {
        for (V& v : vs) add(std::move(v));
    }
    // The output `name` of a sub-model, read when the step ends: the model's unit and type, the
    // drive's description and display unit.
    template <class Sub>
    void at_end(Sub M::*sub, const char* name, const char* display_unit, const char* description) {
        const fmi::Variable<Sub>* v = fmi::find_variable<Sub>(name);
        if (v == nullptr || v->causality != Causality::output)
            throw std::logic_error(std::string("IpmsmDrive: no model output ") + name);
        V f = fmi::forward_variable(sub, *v);
        f.variability = Variability::discrete;
        f.display_unit = display_unit;
        f.description = description;
        add(std::move(f));
    }
    // The parameters of a table (a model's or a part's) from `first` to `last` (all by default)
    // that the drive does not have yet, each forwarded to every model that has it.
    template <class X>
    void parameters(const std::vector<fmi::Variable<X>>& vars, const char* first = nullptr,
                    const char* last = nullptr) {
        bool in = first == nullptr;
        for (const auto& v : vars) {
            in = in || std::string(v.name) == first;
            const bool settable = v.causality == Causality::parameter || v.causality == Causality::structural_parameter;
            if (in && settable && names_.count(v.name) == 0) add(parameter(v.name, controller_, plant_));
            if (in && last != nullptr && std::string(v.name) == last) return;
        }
        if (!in || last != nullptr) throw std::logic_error(std::string("IpmsmDrive: no parameters ") + first);
    }

    std::vector<V> rows;

private:
    ControllerModel M::*controller_;
    PlantModel M::*plant_;
    std::set<std::string> names_;
};

// A sub-model's log lines say which model wrote them. Both models read the same map and
// parameters, so both warn about the same things (a map not legal outside the operating region,
// metadata that differ from a parameter): a warning identical to one the other model gave reaches
// the importer once, with the prefix of the model that gave it first.
fmi::Context prefixed(const fmi::Context& c, const std::string& who,
                      const std::shared_ptr<DriveModel::WarningsGiven>& given) {
    fmi::Context s = c;
    if (c.log_info) s.log_info = [f = c.log_info, who](const std::string& m) { f(who + ": " + m); };
    if (c.log_warning)
        s.log_warning = [f = c.log_warning, who, given](const std::string& m) {
            const auto [it, first] = given->emplace(m, who);
            if (first || it->second == who) f(who + ": " + m);
        };
    return s;
}

}  // namespace

const std::vector<V>& DriveModel::variables() {
    static const std::vector<V> table = [] {
        Table t(&M::controller_, &M::plant_);
        // inputs: those of the coupling description's external inputs
        t.add(of_models("T_ref", &M::T_ref));
        t.add(of_models("w_m", &M::w_m));
        t.add(of_models("u_dc", &M::u_dc));
        t.add(of_models("T_magnet", &M::T_magnet));
        t.add(of_models("T_winding", &M::T_winding));
        t.add_all({
            // outputs: means over the last communication step
            {"T_shaft", &M::T_shaft, Causality::output, Variability::discrete, "N.m", "",
             "Shaft torque (T_e less the iron-loss drag), mean over the last communication step (exact integral)"},
            {"T_e", &M::T_e, Causality::output, Variability::discrete, "N.m", "",
             "Electromagnetic torque, mean over the last communication step (exact integral)"},
            {"i_dc", &M::i_dc, Causality::output, Variability::discrete, "A", "",
             "DC-link current drawn by the inverter, losses included (+ motoring), mean over the last communication "
             "step"},
            {"P_dc", &M::P_dc, Causality::output, Variability::discrete, "W", "kW",
             "DC power drawn by the inverter (machine input + inverter loss), mean over the last communication step"},
            {"P_mech", &M::P_mech, Causality::output, Variability::discrete, "W", "kW",
             "Shaft power, mean over the last communication step (exact integral)"},
            {"P_cu", &M::P_cu, Causality::output, Variability::discrete, "W", "kW",
             "Copper loss, mean over the last communication step (exact integral)"},
            {"P_fe", &M::P_fe, Causality::output, Variability::discrete, "W", "kW",
             "Iron loss, mean over the last communication step (exact integral)"},
            {"P_elec", &M::P_elec, Causality::output, Variability::discrete, "W", "kW",
             "Electrical input power of the machine 1.5 (u_d i_d + u_q i_q) = P_dc - P_inv, mean over the last "
             "communication step"},
            {"P_inv", &M::P_inv, Causality::output, Variability::discrete, "W", "kW",
             "Inverter conduction and switching loss, mean over the last communication step (per inner step: the "
             "current sampled at its end, the inner step's mean AC power)"},
            // outputs: integrals since the start
            {"E_dc", &M::E_dc, Causality::output, Variability::discrete, "J", "Wh",
             "DC energy drawn since the start: the machine's electrical input energy (exact integral) plus the "
             "inverter's loss (P_inv sample_time per inner step)"},
            {"E_mech", &M::E_mech, Causality::output, Variability::discrete, "J", "Wh", "Shaft energy since the start"},
            {"E_cu", &M::E_cu, Causality::output, Variability::discrete, "J", "Wh",
             "Copper-loss energy since the start"},
            {"E_fe", &M::E_fe, Causality::output, Variability::discrete, "J", "Wh", "Iron-loss energy since the start"},
            {"E_inv", &M::E_inv, Causality::output, Variability::discrete, "J", "Wh",
             "Inverter-loss energy since the start"},
        });
        // outputs: the models' at the end of the step (publish_end)
        t.at_end(&M::controller_, "T_cmd", "",
                 "Torque commanded by the controller (T_ref clamped to the limits), at the end of the step");
        t.at_end(&M::controller_, "T_max", "",
                 "Largest torque magnitude reachable, with the sign of T_ref, at the end of the step");
        t.at_end(&M::plant_, "i_d", "", "d-axis stator current, at the end of the step");
        t.at_end(&M::plant_, "i_q", "", "q-axis stator current, at the end of the step");
        t.at_end(&M::controller_, "i_d_ref", "", "d-axis current command, at the end of the step");
        t.at_end(&M::controller_, "i_q_ref", "", "q-axis current command, at the end of the step");
        t.at_end(&M::controller_, "region", "",
                 "The controller's operating region at the end of the step (as IpmsmController.region)");
        t.at_end(&M::controller_, "u_ratio", "",
                 "The controller's voltage command relative to the inverter's linear range u_dc/sqrt(3), at the end of "
                 "the step (1: voltage-limited)");
        // the drive's parameters, then the models' (forwarded, value references in the order they came)
        t.add_all({
            {"sample_time", &M::sample_time, Causality::parameter, Variability::fixed, "s", "ms",
             "Sample time of the controller, and step of the inner coupling; a communication step must be a whole "
             "multiple of it",
             1e-7, kMaxSampleTime},
        });
        t.parameters(fmi::part_table<InverterParams>());
        t.parameters(ControllerModel::variables(), "method", "current_bandwidth");
        t.parameters(PlantModel::variables(), "flux_map", "cvode_max_steps");
        t.parameters(ControllerModel::variables(), "command_check", "command_check");
        t.at_end(&M::controller_, "check_failures", "",
                 "Commands that failed the controller's check on the map since the start (docs/controller.md)");
        // the thermal network (docs/thermal.md)
        t.add(of_models("T_coolant", &M::T_coolant));
        t.add(of_models("T_ambient", &M::T_ambient));
        t.at_end(&M::plant_, "theta_winding", "degC",
                 "Winding temperature at the end of the step: the thermal network's (thermal_model), else the "
                 "T_winding input");
        t.at_end(&M::plant_, "theta_magnet", "degC",
                 "Magnet temperature at the end of the step: the thermal network's (thermal_model), else the T_magnet "
                 "input");
        t.at_end(&M::plant_, "theta_stator_yoke", "degC",
                 "Stator-yoke temperature at the end of the step (thermal_model; else the T_winding input)");
        t.at_end(&M::plant_, "theta_stator_tooth", "degC",
                 "Stator-tooth temperature at the end of the step (thermal_model; else the T_winding input)");
        t.at_end(&M::plant_, "P_coolant", "kW",
                 "Heat into the coolant, mean over the last communication step (thermal_model; else 0)");
        t.at_end(&M::plant_, "E_coolant", "Wh", "Heat into the coolant since the start (thermal_model; else 0)");
        t.at_end(&M::plant_, "E_ambient", "Wh", "Heat into the ambient air since the start (thermal_model; else 0)");
        t.at_end(&M::plant_, "E_stored", "Wh",
                 "Heat stored in the thermal network since the start: E_cu + E_fe = E_stored + E_coolant + E_ambient "
                 "(thermal_model; else 0)");
        t.parameters(PlantModel::variables(), "thermal_model", "I_rms_ref");
        // the controller's temperatures and derating (docs/thermal.md, "Controller")
        t.at_end(&M::controller_, "derating", "",
                 "The controller's thermal factor of the torque limit at the end of the step (1: none; T_max and T_cmd "
                 "include it)");
        t.add_all({
            {"T_magnet_estimate_error", &M::T_magnet_estimate_error, Causality::parameter, Variability::fixed, "K",
             "degC",
             "The controller's magnet temperature is the machine's (the thermal network's, or the T_magnet input) plus "
             "this: the error of a drive's estimate",
             -200.0, 200.0, false, true},
        });
        t.parameters(ControllerModel::variables(), "T_winding_max", "derating_margin");
        // the inverter's safe states (docs/spec/INTERFACE.md, "Faults"; docs/faults.md)
        t.add_all({
            {"fault", &M::fault, Causality::input, Variability::discrete, "", "",
             "true: the inverter must stop switching; the drive stops its current regulator and enters safe_state "
             "(false again: the regulator restarts from the measured currents)"},
            {"safe_state", &M::safe_state, Causality::parameter, Variability::fixed, "", "",
             "The inverter's state in a fault: 0 by speed (freewheeling while the back-EMF's line-to-line peak stays "
             "below u_dc, active short circuit above, and from freewheeling to it when the speed rises past that in "
             "the fault), 1 always freewheeling, 2 always active short circuit",
             0.0, 2.0},
            {"inverter_state", &M::inverter_state, Causality::output, Variability::discrete, "", "",
             "The inverter's state over the last step: 0 switching, 1 freewheeling, 2 active short circuit (the "
             "plant's inverter_state)"},
            {"i_peak", &M::i_peak, Causality::output, Variability::discrete, "A", "",
             "The largest current magnitude |i| at the inner steps' ends since the last fault began (0 before any)"},
        });
        t.parameters(PlantModel::variables(), "i_d_demag", "i_d_demag");
        // least-loss control (docs/spec/INTERFACE.md): the command's predicted loss and the objective
        t.at_end(&M::controller_, "P_loss_cmd", "kW",
                 "The controller's command's predicted steady-state loss P_cu + P_fe + P_inv, at the end of the step");
        t.parameters(ControllerModel::variables(), "objective", "objective");
        // the plant's resistance (its copper loss's): what a master needs to turn P_cu into |i|
        t.at_end(
            &M::plant_, "R_s_T", "",
            "The stator phase resistance at the winding temperature: the plant's over the last inner step, that of "
            "its copper loss");
        // Every other parameter of the models, as they add them (a new motor parameter lands here by
        // itself). The drive's own new variables go before this line while it adds nothing; once a
        // release has recorded what it added (tests/data/value_references_*.json), place those above
        // by name first, so that no value reference moves.
        t.parameters(ControllerModel::variables());
        t.parameters(PlantModel::variables());
        return t.rows;
    }();
    return table;
}

void DriveModel::publish_end() {
    controller_.observe();  // of the step's last sample only: the drive reads it here
}

DriveModel::DriveModel(const fmi::Context& context)
    : warnings_given_(std::make_shared<WarningsGiven>()),
      controller_(prefixed(context, "controller", warnings_given_)),
      plant_(prefixed(context, "plant", warnings_given_)) {
    controller_.observe_each_step = false;  // publish_end() observes, once per communication step
    plant_.thermal_each_step = false;       // do_step heats the network once per communication step
    // Start values: the models' own; where both have a parameter, the plant's, now the controller's too.
    for (const V& v : variables())
        if (v.causality == Causality::parameter || v.causality == Causality::structural_parameter)
            fmi::copy_value(*this, *this, v);
    T_ref = controller_.T_ref;
    u_dc = controller_.u_dc;
    w_m = plant_.w_m;
    T_magnet = plant_.T_magnet;
    T_winding = plant_.T_winding;
    T_coolant = plant_.T_coolant;
    T_ambient = plant_.T_ambient;
}

void DriveModel::check_voltage_command() const {
    const double u = std::hypot(controller_.u_d_ref, controller_.u_q_ref);
    const double u_lim = linear_range(controller_.u_dc);
    if (!(u <= u_lim * (1.0 + 1e-12)))  // the limit's rounding
        throw fmi::Error("serialised FMU state: the controller's voltage command |u_ref| = " + fmi::number_text(u) +
                         " V is beyond the inverter's linear range u_dc / sqrt 3 = " + fmi::number_text(u_lim) +
                         " V at its u_dc = " + fmi::number_text(controller_.u_dc) + " V; not restored");
}

coupling::CoupledModels& DriveModel::coupled() {
    if (!coupled_.models) {
        const coupling::Coupling& c = drive_coupling();
        std::vector<coupling::ModelUnit> units;
        for (const coupling::Unit& u : c.units) {
            if (u.model_identifier == PlantModel::model_identifier)
                units.push_back(coupling::model_unit(plant_));
            else if (u.model_identifier == ControllerModel::model_identifier)
                units.push_back(coupling::model_unit(controller_));
            else
                throw fmi::Error("the drive's coupling description has a unit " + u.model_identifier +
                                 " it does not hold");
        }
        coupled_.models = std::make_unique<coupling::CoupledModels>(c, std::move(units), sample_time);
    }
    coupled_.models->resume_at(k_);  // k_ is the state (a deserialised one too)
    return *coupled_.models;
}

void DriveModel::hold_inputs() {
    coupling::CoupledModels& cm = coupled();
    cm.hold("T_ref", T_ref);
    cm.hold("w_m", w_m);
    cm.hold("u_dc", u_dc);
    cm.hold("T_magnet", T_magnet);
    cm.hold("T_winding", T_winding);
    plant_.T_coolant = T_coolant;  // the plant's alone: not in the coupling description
    plant_.T_ambient = T_ambient;
    // The controller's temperatures: the network's where it runs (its state at the step's start,
    // as the plant uses it over the step), else the inputs, as the plant's; the magnets' as
    // estimated, with the estimate's error.
    const bool network = plant_.thermal_on();
    controller_.T_winding = network ? plant_.theta_winding : T_winding;
    controller_.T_magnet = (network ? plant_.theta_magnet : T_magnet) + T_magnet_estimate_error;
}

int DriveModel::next_inverter_state() const {
    if (!fault) return static_cast<int>(InverterState::switching);
    const auto forced = static_cast<InverterState>(safe_state);
    if (forced != InverterState::switching) return safe_state;
    // by speed: ASC where the bridge would conduct; once in ASC, ASC until the fault clears
    if (inverter_state == static_cast<int>(InverterState::asc)) return inverter_state;
    return static_cast<int>(plant_.back_emf_line_peak() >= u_dc ? InverterState::asc : InverterState::freewheeling);
}

void DriveModel::exit_initialization() {
    coupled_.models.reset();  // sample_time is final now
    k_ = 0;
    hold_inputs();
    inverter_state = 0;
    plant_.inverter_state = 0;
    coupled().initialise();
    if (fault) {  // a fault from the start: the plant's state from its initialised magnet flux
        inverter_state = plant_.inverter_state = next_inverter_state();
        controller_.restart_regulator();
    }
    i_peak = fault ? std::hypot(plant_.i_d, plant_.i_q) : 0.0;
    k_ = coupled().k();
    // The outputs before the first step: the plant's values at the start, nothing integrated.
    P_inv = plant_.P_inv;
    T_shaft = plant_.T_shaft, T_e = plant_.T_e, P_mech = plant_.P_mech, P_cu = plant_.P_cu, P_fe = plant_.P_fe;
    P_elec = plant_.P_elec;
    P_dc = P_elec + P_inv;
    i_dc = P_dc / u_dc;
    E_dc = E_mech = E_cu = E_fe = E_inv = 0.0;
    publish_end();
}

void DriveModel::do_step(double t, double h) {
    // h = n sample_time; the tolerance covers a master's h = t_{k+1} - t_k at large t.
    const double n_real = h / sample_time;
    if (!(n_real <= max_samples_per_step + 0.5)) {  // NaN too; before llround, which overflows
        std::ostringstream os;
        os << "the communication step " << fmi::number_text(h) << " s is more than "
           << fmi::number_text(max_samples_per_step) << " sample times (sample_time = " << fmi::number_text(sample_time)
           << " s): one DoStep computes at most that many; step in parts";
        throw fmi::Error(os.str());
    }
    const long long n = std::llround(n_real);
    const double tolerance =
        std::max(1e-9 * sample_time, 8.0 * std::numeric_limits<double>::epsilon() * (std::abs(t) + h));
    if (n < 1 || std::abs(static_cast<double>(n) * sample_time - h) > tolerance) {
        std::ostringstream os;
        os << "the communication step " << fmi::number_text(h)
           << " s is not a whole multiple of sample_time = " << fmi::number_text(sample_time) << " s ("
           << fmi::number_text(n_real)
           << " sample times): the controller runs at sample_time; use a step of n sample_time";
        throw fmi::Error(os.str());
    }
    hold_inputs();
    coupling::CoupledModels& cm = coupled();
    // The plant integrates its powers exactly over each inner step (its E_*, T_e_impulse): the
    // step's means are their increases over h. The inverter's loss is the plant's, defined per
    // inner step (one PWM period): from the phase current sampled at its end, as the controller
    // samples it, and the inner step's mean AC power; so E_dc = E_elec + E_inv by construction.
    const double E_elec0 = plant_.E_elec, E_mech0 = plant_.E_mech, E_cu0 = plant_.E_cu, E_fe0 = plant_.E_fe;
    const double impulse0 = plant_.T_e_impulse;
    double s_P_inv = 0;
    const int next = next_inverter_state();
    if (next != 0 && inverter_state == 0) i_peak = std::hypot(plant_.i_d, plant_.i_q);  // a fault begins
    inverter_state = plant_.inverter_state = next;
    double plant_steps = 0;  // the work bound (max_plant_steps_per_step)
    for (long long j = 0; j < n; ++j) {
        cm.step();
        s_P_inv += plant_.P_inv;
        if (next != 0) {  // the regulator stopped: it restarts from each sample's currents
            controller_.restart_regulator();
            i_peak = std::max(i_peak, std::hypot(plant_.i_d, plant_.i_q));
        }
        plant_steps += plant_.cvode_steps;
        if (plant_steps > max_plant_steps_per_step) {
            std::ostringstream os;
            os << "the communication step " << fmi::number_text(h) << " s needed more than "
               << fmi::number_text(max_plant_steps_per_step) << " internal steps of the plant after "
               << fmi::number_text(static_cast<double>(j + 1) * sample_time)
               << " s: one DoStep computes at most that many (its wall time is bounded); step in parts, or "
                  "loosen rtol/atol";
            throw fmi::Error(os.str());
        }
    }
    E_inv = plant_.E_inv;
    k_ = cm.k();
    // the thermal network once over the whole step, with the step's exact loss integrals (its
    // temperatures set R_s and the magnet flux of the next step: a lag of h against its 15 s and
    // longer time constants)
    plant_.advance_thermal(h, plant_.E_cu - E_cu0, plant_.E_fe - E_fe0);
    P_elec = (plant_.E_elec - E_elec0) / h;
    P_mech = (plant_.E_mech - E_mech0) / h;
    P_cu = (plant_.E_cu - E_cu0) / h;
    P_fe = (plant_.E_fe - E_fe0) / h;
    T_e = (plant_.T_e_impulse - impulse0) / h;
    T_shaft = w_m != 0.0 ? T_e - P_fe / w_m : T_e;  // the iron-loss drag at the held speed
    P_inv = s_P_inv / static_cast<double>(n);
    P_dc = P_elec + P_inv;
    i_dc = P_dc / u_dc;
    E_mech = plant_.E_mech;
    E_cu = plant_.E_cu;
    E_fe = plant_.E_fe;
    E_dc = plant_.E_elec + E_inv;
    publish_end();
}

}  // namespace ipmsm
