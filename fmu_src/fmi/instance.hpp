// One FMU instance (an fmi2Component or fmi3Instance): the model, where the instance is in the FMI state machine
// and in time, its logging, and the undo of a failed model call. README.md in this folder says
// what the glue does with it.
#pragma once

#include <cmath>
#include <cstdint>
#include <exception>
#include <memory>
#include <new>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

#include "fmi2Functions.h"
#include "fmi2_support.hpp"
#include "fmi3FunctionTypes.h"
#include "log_text.hpp"
#include "model.hpp"
#include "standard.hpp"
#include "variable.hpp"

namespace fmi::glue {

template <class M>
const std::vector<Variable<M>>& variables() {
    static const std::vector<Variable<M>>& table = M::variables();
    return table;
}

// Real variables the model computes (outputs and locals): they must stay finite.
template <class M>
const std::vector<const Variable<M>*>& computed_reals() {
    static const std::vector<const Variable<M>*> list = [] {
        std::vector<const Variable<M>*> l;
        for (const auto& v : variables<M>())
            if (type_of(v) == Type::Real && is_computed(v.causality)) l.push_back(&v);
        return l;
    }();
    return list;
}

// --- logging ---
inline constexpr unsigned bit(LogCategory c) { return 1u << static_cast<unsigned>(c); }
// loggingOn = true without a list of categories: everything but the call trace.
inline constexpr unsigned default_categories = bit(LogCategory::events) | bit(LogCategory::warning) |
                                               bit(LogCategory::discard) | bit(LogCategory::error) |
                                               bit(LogCategory::fatal);

// The importer's logger: FMI 2.0's takes the message as a printf format and the instance's name,
// FMI 3.0's takes the message as is. The glue's statuses are fmi2Status; fmi3Status has the same
// values for the same names (fmi3_functions.hpp checks that).
struct Logger {
    fmi2CallbackLogger fmi2 = nullptr;
    fmi3LogMessageCallback fmi3 = nullptr;
    void* environment = nullptr;
};

inline void call_logger(const Logger& logger, const char* instance, fmi2Status status, LogCategory category,
                        const std::string& message) noexcept {
    if (logger.fmi2 == nullptr && logger.fmi3 == nullptr) return;
    try {
        // Valid UTF-8 and bounded (log_text.hpp); line breaks kept.
        const std::string safe = utf8_excerpt(message, kMaxLogChars, false);
        const char* name = log_categories[static_cast<unsigned>(category)].name;
        if (logger.fmi3 != nullptr) {
            logger.fmi3(logger.environment, static_cast<fmi3Status>(status), name, safe.c_str());
            return;
        }
        // FMI 2.0: '%' doubled, the logger treats the message as a printf format.
        std::string text;
        text.reserve(safe.size() + 8);
        for (char ch : safe) {
            text += ch;
            if (ch == '%') text += '%';
        }
        logger.fmi2(logger.environment, instance != nullptr ? instance : "", status, name, text.c_str());
    } catch (...) {}
}

// An FMU state (fmi2FMUstate): a copy of the model plus where the instance was.
template <class M>
struct Snapshot {
    M model;
    Phase phase;
    double start_time;
    double time;
    std::vector<char> bytes;  // the serialised form, made on the first request
};

template <class M>
class Instance {
public:
    // First member: lets the glue recognise its own instances (and not the other FMU's, nor the
    // same model's under the other standard).
    static constexpr std::uint64_t tag_of(const Standard& s) { return fnv1a(M::guid) ^ 0x494e5354414e4345ull ^ s.salt; }
    std::uint64_t tag;

    const Standard& standard;
    const std::string name;
    const Logger logger;
    unsigned categories;  // enabled log categories, bit(LogCategory)

    const Context context;  // what fresh models (fmi2Reset) are made with
    M model;
    Phase phase = Phase::instantiated;
    double start_time = 0.0;  // fmi2SetupExperiment's startTime
    double time = 0.0;        // where the next step starts

    std::vector<std::string> strings;  // what fmi2GetString returned last
    std::unique_ptr<M> initial;        // Initialization Mode: the model as exit_initialization() leaves it
    std::unordered_set<Snapshot<M>*> snapshots;

    Instance(const Standard& spoken, const char* instance_name, Logger log, bool logging_on, std::string resource_dir)
        : tag(tag_of(spoken)),
          standard(spoken),
          name(instance_name),
          logger(log),
          categories(logging_on ? default_categories : 0u),
          context(make_context(std::move(resource_dir))),
          model(context),
          backup_(model) {}

    ~Instance() {
        for (auto* s : snapshots) delete s;
        *static_cast<volatile std::uint64_t*>(&tag) = 0;  // best effort against a freed component
    }
    Instance(const Instance&) = delete;
    Instance& operator=(const Instance&) = delete;

    void log(fmi2Status status, LogCategory category, const std::string& message) noexcept {
        const bool always = status == fmi2Error || status == fmi2Fatal;
        if (!always && !(categories & (bit(category) | bit(LogCategory::all)))) return;
        call_logger(logger, name.c_str(), status, category, message);
    }
    bool tracing() const { return (categories & bit(LogCategory::all)) != 0; }

    static double value_of(const M& m, const Variable<M>* v) { return fmi::value_of<double>(m, *v); }
    // The first computed Real of m that is not finite, or nullptr.
    static const Variable<M>* first_non_finite(const M& m) {
        for (const Variable<M>* v : computed_reals<M>())
            if (!std::isfinite(value_of(m, v))) return v;
        return nullptr;
    }

    // The undo: runs f (a model call) so that, if it throws or leaves a computed Real non-finite,
    // the model is as before (the glue's copy of it is put back). what() describes the call for
    // the log; it is called only on failure (a step's description costs as much as the glue's
    // whole per-step work otherwise).
    template <class F, class W>
    void undoable(F&& f, W&& what) {
        backup_ = model;
        try {
            f();
            if (const Variable<M>* v = first_non_finite(model))
                throw Error(std::string("the model computed ") + v->name + " = " + number_text(value_of(model, v)) +
                            ", not a finite number");
        } catch (const std::bad_alloc&) {
            // The model asked for more memory than there is (a table, a map): undone like any
            // failure, the instance stays usable; fatal only if the undo itself fails.
            restore();
            if (phase == Phase::error) throw;
            throw Error(
                undone("out of memory (the model asked for more memory than the process can get: "
                       "a parameter or data file asks for too large a table or map)",
                       what()));
        } catch (const std::exception& e) {
            restore();
            throw Error(undone(e.what(), what()));
        } catch (...) {
            restore();
            throw Error(undone("unknown exception (not a std::exception)", what()));
        }
    }

    // Initialization Mode: the model as fmi2ExitInitializationMode will leave it, for the Get of an
    // output or local (README.md). Computed on a copy, with the model's logging muted; kept until
    // a Set, fmi2SetFMUstate, fmi2Reset or fmi2ExitInitializationMode drops it.
    const M& initial_model() {
        if (initial) return *initial;
        auto m = std::make_unique<M>(model);
        struct Mute {
            bool& q;
            explicit Mute(bool& flag) : q(flag) { q = true; }
            ~Mute() { q = false; }
        } mute(quiet_);
        const char* why = "the outputs cannot be computed in Initialization Mode with the values set so far: ";
        try {
            m->exit_initialization();
        } catch (const std::bad_alloc&) {  // on a copy: the instance is untouched
            throw Error(why +
                        std::string("out of memory (a parameter or data file asks for too large a table or map; ") +
                        standard.exit_initialization_mode + " would fail the same way)");
        } catch (const std::exception& e) {
            throw Error(why + std::string(e.what()) + " (" + standard.exit_initialization_mode +
                        " would fail the same way)");
        } catch (...) {
            throw Error(why + std::string("unknown exception (not a std::exception)"));
        }
        if (const Variable<M>* v = first_non_finite(*m))
            throw Error(why + std::string("the model computes ") + v->name + " = " + number_text(value_of(*m, v)));
        initial = std::move(m);
        return *initial;
    }

private:
    M backup_;            // the model before the call undoable() runs
    bool quiet_ = false;  // the model's log messages are dropped (while computing `initial`)

    Context make_context(std::string resource_dir) {
        Context c;
        c.instance_name = name;
        c.resource_dir = std::move(resource_dir);
        c.log_info = [this](const std::string& m) {
            if (!quiet_) log(fmi2OK, LogCategory::events, m);
        };
        c.log_warning = [this](const std::string& m) {
            if (quiet_) return;
            log(fmi2Warning, LogCategory::warning, m);
        };
        return c;
    }

    std::string undone(const std::string& cause, const std::string& what) const {
        if (phase == Phase::error) return cause + " [" + what + "; the model could not be restored: state error]";
        return cause + " [" + what + " was undone: the instance is as before the call and can be used again]";
    }

    void restore() noexcept {
        try {
            using std::swap;
            swap(model, backup_);
        } catch (...) {
            phase = Phase::error;
        }
    }
};

}  // namespace fmi::glue
