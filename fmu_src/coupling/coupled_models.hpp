// The coupling description run on the models themselves, without FMI: each unit's model (a
// class with a variable table, exit_initialization() and do_step(t, h), fmi/model.hpp), its
// variables found by the description's names. For a single FMU that holds both models (the
// IpmsmDrive of issue 14) and for measuring the models' own cost (bench/cosim_profile.cpp, which
// checks that this loop and the FMI master give the same numbers bit for bit).
//
// The same semantics as the FMI masters (ipmsm_drive.coupling): Jacobi at a fixed step h,
// t_k = k h; initialisation unit by unit in the description's order, each taking its connected
// inputs from the units already initialised.
#pragma once

#include <functional>
#include <map>
#include <stdexcept>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "coupling/coupling.hpp"
#include "fmi/variable.hpp"

namespace ipmsm::coupling {

// One unit's model as the loop sees it: its Real variables by name, its two calls.
struct ModelUnit {
    std::function<double*(const std::string& name)> real;  // nullptr if it has no such Real
    std::function<void()> exit_initialization;
    std::function<void(double t, double h)> do_step;
};

// A ModelUnit on `model` (which must outlive it), through Model::variables().
template <class Model>
ModelUnit model_unit(Model& model) {
    return {[&model](const std::string& name) -> double* {
                const auto* v = fmi::find_variable<Model>(name);
                const auto* a = v != nullptr ? std::get_if<fmi::Access<Model, double>>(&v->member) : nullptr;
                return a != nullptr && a->member != nullptr ? &(model.*(a->member)) : nullptr;
            },
            [&model] { model.exit_initialization(); }, [&model](double t, double h) { model.do_step(t, h); }};
}

class CoupledModels {
public:
    // units: one per unit of the description, in its order. std::invalid_argument names a
    // variable the models lack.
    CoupledModels(const Coupling& coupling, std::vector<ModelUnit> units, double h) : units_(std::move(units)), h_(h) {
        if (units_.size() != coupling.units.size())
            throw std::invalid_argument("the coupling has " + std::to_string(coupling.units.size()) + " units, " +
                                        std::to_string(units_.size()) + " models given");
        auto find = [&](const Port& p) {
            double* x = units_[static_cast<size_t>(coupling.unit_index(p.unit))].real(p.variable);
            if (x == nullptr)
                throw std::invalid_argument("coupling: the " + p.unit + " has no Real '" + p.variable + "'");
            return x;
        };
        for (const ExternalInput& e : coupling.inputs)
            for (const Port& p : e.to) inputs_[e.name].push_back(find(p));
        for (const Connection& c : coupling.connections)
            links_.push_back({find(c.to), find(c.from), static_cast<size_t>(coupling.unit_index(c.to.unit)),
                              static_cast<size_t>(coupling.unit_index(c.from.unit))});
    }

    // Holds the external input `name` at `value` (in every input it feeds) until the next hold.
    void hold(const std::string& name, double value) {
        const auto it = inputs_.find(name);
        if (it == inputs_.end()) throw std::invalid_argument("coupling: no external input '" + name + "'");
        for (double* x : it->second) *x = value;
    }

    // Unit by unit: its connected inputs from the units already initialised, exit_initialization().
    void initialise() {
        for (size_t i = 0; i < units_.size(); ++i) {
            for (const Link& l : links_)
                if (l.to_unit == i && l.from_unit < i) *l.to = *l.from;
            units_[i].exit_initialization();
        }
        k_ = 0;
    }

    // The step from t_k = k h: every connected input gets its output's value after the previous
    // step, then every unit steps; k += 1.
    void step() {
        for (const Link& l : links_) *l.to = *l.from;
        const double t = static_cast<double>(k_) * h_;
        for (ModelUnit& u : units_) u.do_step(t, h_);
        ++k_;
    }

    long long k() const { return k_; }
    // Continues at step k (a copy of the models, or a restored FMU state, that had made k steps).
    void resume_at(long long k) { k_ = k; }

private:
    struct Link {
        double* to;
        const double* from;
        size_t to_unit, from_unit;
    };
    std::vector<ModelUnit> units_;
    double h_;
    long long k_ = 0;
    std::map<std::string, std::vector<double*>> inputs_;
    std::vector<Link> links_;
};

}  // namespace ipmsm::coupling
