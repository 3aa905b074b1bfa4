// ToyLag: the test fixture of the FMI 2.0 glue (tests/python/test_fmi_glue.py), not a product.
// A first-order lag y' = (k·u − y)/tau, solved exactly for u held over each step (n_sub equal
// sub-steps), plus angle' = w. It uses every variable kind the glue supports, a resource file, a
// warning, internal state beyond its variables, and an input `fault` that makes do_step misbehave
// in each way the glue must contain.
#include <cmath>
#include <fstream>
#include <new>
#include <stdexcept>
#include <string>
#include <vector>

#include "model.hpp"
#include "variable.hpp"

class ToyLag {
public:
    static constexpr const char* model_identifier = "ToyLag";
    static constexpr const char* guid = "{dd347a2e-2c19-4084-89b3-2dd3d181ae56}";
    static constexpr const char* description = "First-order lag: test fixture of the ipmsm-fmu FMI 2.0 glue";
    static constexpr double default_step_size = 0.01;
    static constexpr double default_stop_time = 1.0;

    static const std::vector<fmi::Variable<ToyLag>>& variables() {
        using fmi::Causality;
        using fmi::Variability;
        static const std::vector<fmi::Variable<ToyLag>> v = {
            {"u", &ToyLag::u, Causality::input, Variability::continuous, "V", "", "Input of the lag", -100, 100},
            {"w", &ToyLag::w, Causality::input, Variability::continuous, "rad/s", "rpm", "Speed integrated into angle"},
            {"hold", &ToyLag::hold, Causality::input, Variability::discrete, "", "",
             "true: y keeps its value this step"},
            {"fault", &ToyLag::fault, Causality::input, Variability::discrete, "", "",
             "Test hook: 1 throw fmi::Error, 2 throw std::runtime_error, 3 throw an int, 4 NaN output, 5 bad_alloc", 0,
             5},
            {"tau", &ToyLag::tau, Causality::parameter, Variability::fixed, "s", "", "Time constant", 0, 1e6, true},
            {"k", &ToyLag::k, Causality::parameter, Variability::tunable, "1", "", "Gain", -10, 10},
            {"y0", &ToyLag::y0, Causality::parameter, Variability::fixed, "V", "", "Initial state", -100, 100},
            {"n_sub", &ToyLag::n_sub, Causality::parameter, Variability::fixed, "", "", "Sub-steps per step", 1,
             10000000},
            {"offset_file", &ToyLag::offset_file, Causality::parameter, Variability::fixed, "", "",
             "Resource file holding a number added to y; empty: none"},
            {"T_amb", &ToyLag::T_amb, Causality::parameter, Variability::tunable, "K", "degC",
             "Ambient temperature that T_out adds y to", 0, 1000, true},
            {"y", &ToyLag::y, Causality::output, Variability::continuous, "V", "", "Lag output plus offset"},
            {"angle", &ToyLag::angle, Causality::output, Variability::continuous, "rad", "deg", "Integral of w"},
            {"steps", &ToyLag::steps, Causality::output, Variability::discrete, "", "", "Steps taken"},
            {"held", &ToyLag::held, Causality::output, Variability::discrete, "", "", "hold during the last step"},
            {"T_out", &ToyLag::T_out, Causality::output, Variability::continuous, "K", "degC", "T_amb + y"},
            {"y_prev", &ToyLag::y_prev, Causality::local, Variability::continuous, "V", "", "y before the last step"},
        };
        return v;
    }

    explicit ToyLag(const fmi::Context& context) : context_(fmi::share(context)) {}

    void exit_initialization() {
        offset_ = 0.0;
        if (!offset_file.empty()) {
            if (context_->resource_dir.empty())
                throw fmi::Error("offset_file is set but the FMU has no resources directory");
            const std::string path = context_->resource_dir + "/" + offset_file;
            std::ifstream f(path);
            if (!(f >> offset_)) throw fmi::Error("cannot read a number from " + path);
            context_->log_info("offset " + std::to_string(offset_) + " from " + path);
        }
        state_ = y0;
        outputs();
    }

    void do_step(double /*t*/, double h) {
        if (fault != 0) {
            ++steps;  // a misbehaving model: it changes itself before failing, the glue must undo that
            y = 1e300;
            switch (fault) {
                case 1: throw fmi::Error("fault 1: fmi::Error from do_step");
                case 2: throw std::runtime_error("fault 2: std::runtime_error from do_step");
                case 3: throw 3;
                case 4: y = std::nan(""); return;
                default: throw std::bad_alloc();
            }
        }
        if (h > tau) context_->log_warning("step " + std::to_string(h) + " s is longer than tau");
        y_prev = y;
        if (!hold) {
            const double a = std::exp(-(h / n_sub) / tau), target = k * u;
            for (int i = 0; i < n_sub; ++i) state_ = target + (state_ - target) * a;
        }
        angle += w * h;
        ++steps;
        held = hold;
        outputs();
    }

    template <class Field>
    void state_fields(Field&& field) {
        field(state_);
    }

    double u = 0.0, w = 0.0;
    bool hold = false;
    int fault = 0;
    double tau = 0.1, k = 1.0, y0 = 0.0;
    int n_sub = 1;
    std::string offset_file;
    double T_amb = 293.15;
    double y = 0.0, angle = 0.0;
    int steps = 0;
    bool held = false;
    double T_out = 293.15, y_prev = 0.0;

private:
    void outputs() {
        y = state_ + offset_;
        T_out = T_amb + y;
    }
    fmi::SharedContext context_;
    double state_ = 0.0;   // the lag's state without offset: listed by state_fields()
    double offset_ = 0.0;  // loaded data: not saved, exit_initialization() reads it again
};

using ExportedModel = ToyLag;
#include "fmi2_entry_points.inc"
