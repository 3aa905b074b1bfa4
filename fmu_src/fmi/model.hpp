// What an FMU's model must provide to the shared FMI 2.0 glue (README.md in this folder).
//
// A model is a copyable C++ class, free of FMI types:
//
//   class MyModel {
//   public:
//     static constexpr const char* model_identifier = "MyModel";
//     static constexpr const char* guid = "{...}";
//     static constexpr const char* description = "...";
//     static constexpr double default_step_size = 1e-4;   // DefaultExperiment stepSize, s
//     static constexpr double default_stop_time = 1.0;    // DefaultExperiment stopTime, s
//     static const std::vector<fmi::Variable<MyModel>>& variables();
//
//     explicit MyModel(const fmi::Context& context);  // start values
//     void exit_initialization();  // parameters are final: validate, load data (may throw)
//     void do_step(double t, double h);  // one communication step from t to t + h (may throw)
//     template <class Field>
//     void state_fields(Field&& field);  // field(x) for every member x of the internal state
//     ... members named in variables() (or parts they forward to: variable.hpp) ...
//   };
//
// Contract with the glue:
// - Exceptions are the only error channel: the glue turns fmi::Error and std::exception into
//   fmi2Error plus a log message, at one boundary.
// - Undo is the glue's: before exit_initialization() and do_step() it copy-assigns the model,
//   and puts that copy back if the call throws or leaves an output or local Real non-finite. A
//   model may therefore fail half-way; it must keep copy-assignment cheap (it runs once per
//   communication step: large read-only data behind std::shared_ptr<const T>).
// - The FMU state is the variables (the table) plus the internal state that state_fields()
//   lists, once, in a fixed order: plain members (double, int, bool, an enum, or a fixed-size
//   array of them) that a step changes beyond the variables. fmi2GetFMUstate copies the whole
//   model; serialisation writes the variables and these fields (fmu_state.hpp). Data that
//   exit_initialization() loads is not state: the glue loads it again when it deserialises a
//   state into an instance that is not initialised (it sets the saved values, calls
//   exit_initialization(), sets them again, then the fields).
//   A field may name what it may hold, field(x, fmi::FieldRange{...}) or field(x, variable) (the
//   model's table entry: the range fmi2SetReal checks): a state is input, not proof, and the glue
//   refuses a deserialised state whose field is outside it (state_stream.hpp).
// - fmi2Reset replaces the model with a fresh MyModel(context).
// - exit_initialization() may also run on a copy of the model in Initialization Mode, to answer a
//   Get of an output (InitialUnknowns) before fmi2ExitInitializationMode: it must have no effect
//   outside the model object but its log messages (which the glue mutes there).
// - The glue validates values before the model sees them: type, causality and state rules,
//   finite Reals, [min, max] from the table. exit_initialization() checks what depends on
//   several values (or on data).
#pragma once

#include <functional>
#include <memory>
#include <stdexcept>
#include <string>

namespace fmi {

// A model's error: the message goes to the FMI log as is.
struct Error : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// What the model may use of its environment. The instance makes it; a model keeps it as a
// SharedContext (below), so that every copy of the model (undo copy, FMU states) and a model
// made outside an instance (tests, benchmarks) refer to a context that lives as long as they do.
struct Context {
    std::string instance_name;
    std::string resource_dir;                             // local path of the FMU's resources/ folder, "" if unknown
    std::function<void(const std::string&)> log_info;     // category logEvents
    std::function<void(const std::string&)> log_warning;  // category logStatusWarning
};

// What a field of a model's internal state may hold (state_fields(), above): [min, max], and a
// whole number if `whole` (a count kept as a double). An int or enum field is checked as its
// integer value: an enum lists its set here.
struct FieldRange {
    const char* name;
    double min, max;
    bool whole = false;
};

// How a model holds its Context: shared by all its copies, read-only.
using SharedContext = std::shared_ptr<const Context>;
inline SharedContext share(const Context& c) { return std::make_shared<const Context>(c); }

}  // namespace fmi
