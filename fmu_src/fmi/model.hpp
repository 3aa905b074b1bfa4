// What an FMU's model must provide to the shared FMI 2.0 glue (fmi2_glue.hpp).
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
//     void save_state(fmi::StateWriter& w) const;  // internal state beyond the variables
//     void load_state(fmi::StateReader& r);
//     ... members named in variables() ...
//   };
//
// Contract with the glue:
// - Exceptions are the only error channel: the glue turns fmi::Error and std::exception into
//   fmi2Error plus a log message, at one boundary. A throwing call must leave the model as it was
//   (compute into locals, commit at the end), so that the instance stays usable.
// - fmi2Reset replaces the model with a fresh MyModel(context).
// - fmi2GetFMUstate copies the model (copy constructor): keep large read-only data behind
//   std::shared_ptr<const T>. Serialisation writes every variable's value plus save_state().
// - Before each do_step and exit_initialization the glue copy-assigns the model to a scratch copy,
//   and swaps it back if the call throws or leaves an output or local Real non-finite: keep
//   copy-assignment cheap (it runs once per communication step) and swap non-throwing.
// - exit_initialization() may also run on a copy of the model in Initialization Mode, to answer a
//   Get of an output (InitialUnknowns) before fmi2ExitInitializationMode: it must have no effect
//   outside the model object but its log messages (which the glue mutes there).
// - The glue validates values before the model sees them: type, causality and state rules,
//   finite Reals, [min, max] from the table. exit_initialization() checks what depends on
//   several values (or on data).
// - Deserialising a state saved after initialisation into an instance not yet initialised: the
//   glue sets the saved values, calls exit_initialization() (to load data), sets the saved values
//   again, then load_state().
#pragma once

#include <cstdint>
#include <cstring>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

namespace fmi {

// A model's error: the message goes to the FMI log as is.
struct Error : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// What the model may use of its environment.
struct Context {
    std::string instance_name;
    std::string resource_dir;  // local path of the FMU's resources/ folder, "" if unknown
    std::function<void(const std::string&)> log_info;     // category logEvents
    std::function<void(const std::string&)> log_warning;  // category logStatusWarning
};

// Byte stream for FMU-state serialisation of a model's internal state.
class StateWriter {
public:
    explicit StateWriter(std::vector<char>& out) : out_(out) {}
    template <class T>
    void put(const T& v) {
        static_assert(std::is_trivially_copyable_v<T>, "put() takes plain values");
        const char* p = reinterpret_cast<const char*>(&v);
        out_.insert(out_.end(), p, p + sizeof(T));
    }
    void put_doubles(const double* v, std::size_t n) {
        put<std::uint64_t>(n);
        const char* p = reinterpret_cast<const char*>(v);
        out_.insert(out_.end(), p, p + n * sizeof(double));
    }
    void put_string(const std::string& s) {
        put<std::uint64_t>(s.size());
        out_.insert(out_.end(), s.begin(), s.end());
    }

private:
    std::vector<char>& out_;
};

class StateReader {
public:
    StateReader(const char* data, std::size_t size) : p_(data), end_(data + size) {}
    template <class T>
    T get() {
        static_assert(std::is_trivially_copyable_v<T>, "get() takes plain values");
        need(sizeof(T));
        T v;
        std::memcpy(&v, p_, sizeof(T));
        p_ += sizeof(T);
        return v;
    }
    void get_doubles(double* v, std::size_t n) {
        if (get<std::uint64_t>() != n) throw Error("serialised FMU state: array size mismatch");
        need(n * sizeof(double));
        std::memcpy(v, p_, n * sizeof(double));
        p_ += n * sizeof(double);
    }
    std::string get_string() {
        const auto n = get<std::uint64_t>();
        need(n);
        std::string s(p_, p_ + n);
        p_ += n;
        return s;
    }
    bool at_end() const { return p_ == end_; }

private:
    void need(std::size_t n) const {
        if (static_cast<std::size_t>(end_ - p_) < n) throw Error("serialised FMU state is truncated");
    }
    const char* p_;
    const char* end_;
};

}  // namespace fmi
