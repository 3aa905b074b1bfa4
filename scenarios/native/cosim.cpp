// ipmsm_cosim: the native FMI 2.0 master of the coupled drive (see cosim.h): the coupling
// description's names resolved to value references, then the Jacobi loop over the units.
// scenarios/master.py (backend "fmpy") makes the same FMI calls in the same order in Python.
#include "cosim.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdarg>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <new>
#include <string>
#include <utility>
#include <vector>

#include "coupling/coupling.hpp"
#include "fmi2Functions.h"
#include "fmu_binary.hpp"

#define IPMSM_COSIM_API extern "C" __attribute__((visibility("default")))

namespace {

const char* status_name(fmi2Status s) {
    switch (s) {
        case fmi2OK: return "fmi2OK";
        case fmi2Warning: return "fmi2Warning";
        case fmi2Discard: return "fmi2Discard";
        case fmi2Error: return "fmi2Error";
        case fmi2Fatal: return "fmi2Fatal";
        case fmi2Pending: return "fmi2Pending";
    }
    return "an unknown fmi2Status";
}

// printf into a std::string of any length ("" if the format is bad); ap is consumed.
std::string vformat(const char* fmt, va_list ap) __attribute__((format(printf, 1, 0)));
std::string vformat(const char* fmt, va_list ap) {
    char buf[1024];
    va_list ap2;
    va_copy(ap2, ap);
    const int n = std::vsnprintf(buf, sizeof buf, fmt, ap);
    std::string s;
    if (n >= 0 && static_cast<size_t>(n) < sizeof buf) {
        s.assign(buf, static_cast<size_t>(n));
    } else if (n >= 0) {
        s.resize(static_cast<size_t>(n) + 1);
        std::vsnprintf(&s[0], s.size(), fmt, ap2);
        s.resize(static_cast<size_t>(n));
    }
    va_end(ap2);
    return s;
}

std::string format(const char* fmt, ...) __attribute__((format(printf, 1, 2)));
std::string format(const char* fmt, ...) {
    va_list ap;
    va_start(ap, fmt);
    std::string s = vformat(fmt, ap);
    va_end(ap);
    return s;
}

struct LogEntry {
    int status;
    std::string category, message;
};

struct Master;

// One FMU of the description, and what the loop reads of it after every step.
struct Unit {
    Master* master = nullptr;
    std::string role, model_identifier, instance_name;
    fmu_binary::Description md;
    fmi2Component component = nullptr;
    fmi2CallbackFunctions callbacks{};
    bool initialised = false;       // fmi2ExitInitializationMode succeeded
    bool fatal = false;             // an fmi2Fatal: only fmi2FreeInstance is allowed
    std::vector<LogEntry> pending;  // logged during the current FMI call

    fmu_binary::Functions fmi;  // the FMU's binary, dlopened; closed with the instance

    // Its external inputs: value references and the fields of ipmsm_cosim_inputs they take.
    std::vector<fmi2ValueReference> external_vr;
    std::vector<double ipmsm_cosim_inputs::*> external_field;
    std::vector<double> external_value;
    std::string external_names;  // "w_m, T_magnet, T_winding", for messages
    // Read after every step: Reals (the connected outputs first, n_connected of them, then the
    // Real probes) and Integers (Integer probes).
    std::vector<fmi2ValueReference> read_real, read_int;
    size_t n_connected = 0;
    std::vector<double> real;
    std::vector<fmi2Integer> integer;

    std::string describe() const { return model_identifier + " (" + role + ", instance '" + instance_name + "')"; }

    std::string type_of(const std::string& name) const {
        const auto it = md.type.find(name);
        return it != md.type.end() ? it->second : "";
    }

    // The value reference of a Real variable; false, with why, if there is none.
    bool real_vr(const std::string& name, fmi2ValueReference& vr, std::string& why) const {
        const auto it = md.vr.find(name);
        if (it == md.vr.end()) return why = model_identifier + " has no variable '" + name + "'", false;
        if (type_of(name) != "Real") return why = model_identifier + "." + name + " is not a Real", false;
        vr = it->second;
        return true;
    }
};

// The connected inputs of one unit fed by one other unit: one fmi2SetReal per step, the values
// straight from the sender's read buffer (its connected outputs are laid out in this order).
struct Feed {
    size_t to, from;  // units
    std::vector<fmi2ValueReference> vr;
    size_t offset;      // into the sender's read buffer
    std::string names;  // "u_d, u_q", for messages
};

struct Probe {
    enum Kind { real, integer, current_abs, current_sq } kind;
    size_t unit, slot;  // where the value is read (current_*: the plant's i_d; i_q at slot2)
    size_t slot2;
};

// The fields of ipmsm_cosim_inputs by name: a description's external input binds to one.
struct InputField {
    const char* name;
    double ipmsm_cosim_inputs::*field;
};
constexpr InputField kInputFields[] = {
    {"T_ref", &ipmsm_cosim_inputs::T_ref},         {"w_m", &ipmsm_cosim_inputs::w_m},
    {"u_dc", &ipmsm_cosim_inputs::u_dc},           {"T_magnet", &ipmsm_cosim_inputs::T_magnet},
    {"T_winding", &ipmsm_cosim_inputs::T_winding},
};

struct Master {
    std::string coupling_text;
    ipmsm::coupling::Coupling coupling;
    bool coupling_read = false;
    double h;
    ipmsm_cosim_log_fn log_fn;
    void* log_user;
    std::vector<Unit> units;  // in the description's order
    std::string error;

    bool resolved = false;
    bool coupled = false;  // initialised: advance may run
    bool stopped = false;  // a step failed: the units are no longer in step
    long long k = 0;
    std::vector<Feed> feeds;
    std::vector<Probe> probes;
    std::vector<double> values, sums;

    Master(const char* text, double h_, ipmsm_cosim_log_fn fn, void* user)
        : coupling_text(text != nullptr ? text : ""), h(h_), log_fn(fn), log_user(user) {}

    bool fail(std::string text) {
        error = std::move(text);
        return false;
    }

    // The description, read on first use (a bad one fails every call that needs it).
    bool read_coupling() {
        if (coupling_read) return true;
        try {
            coupling = ipmsm::coupling::parse(coupling_text);
        } catch (const std::invalid_argument& e) {
            return fail(e.what());
        }
        units = std::vector<Unit>(coupling.units.size());
        for (size_t i = 0; i < units.size(); ++i) {
            units[i].master = this;
            units[i].role = coupling.units[i].role;
            units[i].model_identifier = coupling.units[i].model_identifier;
        }
        coupling_read = true;
        return true;
    }

    // Passes the unit's pending log messages on and clears them; all of them, or (after a
    // failed call, whose error text quotes them) only those below fmi2Warning.
    void flush(Unit& u, bool quoted = false) {
        for (const LogEntry& e : u.pending) {
            if (quoted && e.status >= fmi2Warning) continue;
            if (log_fn != nullptr) {
                log_fn(log_user, u.role.c_str(), u.instance_name.c_str(), e.status, e.category.c_str(),
                       e.message.c_str());
            } else if (e.status >= fmi2Warning) {
                std::fprintf(stderr, "[%s %s %s] %s\n", u.instance_name.c_str(),
                             status_name(static_cast<fmi2Status>(e.status)), e.category.c_str(), e.message.c_str());
            }
        }
        u.pending.clear();
    }

    // The unit's failure text: what failed, then the messages the FMU logged during the call.
    std::string failure(Unit& u, const std::string& what) {
        std::string text = u.describe() + ": " + what;
        bool any = false;
        for (const LogEntry& e : u.pending) {
            if (e.status < fmi2Warning) continue;
            text += any ? "; " : ": ";
            text += e.message;
            any = true;
        }
        if (!any) text += " (the FMU logged no message)";
        flush(u, true);
        return text;
    }

    // After an FMI call: true if it succeeded (fmi2OK, fmi2Warning). Otherwise the error text
    // names the FMU, the function, the time (`when`) and quotes the FMU's log of the call.
    bool check(Unit& u, fmi2Status s, const std::string& function, const std::string& when) {
        if (s == fmi2OK || s == fmi2Warning) {
            if (!u.pending.empty()) flush(u);
            return true;
        }
        if (s == fmi2Fatal) u.fatal = true;
        return fail(failure(u, function + when + " returned " + status_name(s)));
    }

    std::string at_time() const { return format(" at t = %.9g s (step k = %lld)", static_cast<double>(k) * h, k); }

    // The unit of that role; nullptr (and the error set) if there is none or it cannot be used.
    Unit* unit(const char* role, bool need_instance = true) {
        if (!read_coupling()) return nullptr;
        if (role == nullptr) return fail("NULL role"), nullptr;
        const int i = coupling.unit_index(role);
        if (i < 0) return fail(std::string("the coupling has no unit '") + role + "'"), nullptr;
        Unit& u = units[static_cast<size_t>(i)];
        if (need_instance && u.component == nullptr) return fail("the " + u.role + " is not instantiated"), nullptr;
        if (need_instance && u.fatal)
            return fail(u.model_identifier + " reported fmi2Fatal earlier: it can only be freed"), nullptr;
        return &u;
    }

    bool all_instantiated() {
        if (!read_coupling()) return false;
        for (Unit& u : units)
            if (unit(u.role.c_str()) == nullptr) return false;
        return true;
    }

    // The description's names as value references: each unit's external inputs, the feeds and
    // the connected outputs at the front of each unit's read list.
    bool resolve() {
        std::string why;
        for (Unit& u : units) {
            u.external_vr.clear();
            u.external_field.clear();
            u.external_names.clear();
            u.read_real.clear();
            u.read_int.clear();
        }
        for (const auto& input : coupling.inputs) {
            const InputField* field = nullptr;
            for (const InputField& f : kInputFields)
                if (input.name == f.name) field = &f;
            if (field == nullptr)
                return fail("the coupling's external input '" + input.name + "' is not a field of ipmsm_cosim_inputs");
            for (const auto& port : input.to) {
                Unit& u = units[static_cast<size_t>(coupling.unit_index(port.unit))];
                fmi2ValueReference vr;
                if (!u.real_vr(port.variable, vr, why)) return fail("coupling: " + why);
                u.external_vr.push_back(vr);
                u.external_field.push_back(field->field);
                u.external_names += (u.external_names.empty() ? "" : ", ") + port.variable;
            }
        }
        feeds.clear();
        for (size_t to = 0; to < units.size(); ++to) {
            for (size_t from = 0; from < units.size(); ++from) {
                Feed f{to, from, {}, units[from].read_real.size(), ""};
                for (const auto& c : coupling.connections) {
                    if (coupling.unit_index(c.to.unit) != static_cast<int>(to) ||
                        coupling.unit_index(c.from.unit) != static_cast<int>(from))
                        continue;
                    fmi2ValueReference in_vr, out_vr;
                    if (!units[to].real_vr(c.to.variable, in_vr, why) ||
                        !units[from].real_vr(c.from.variable, out_vr, why))
                        return fail("coupling: " + why);
                    f.names += (f.vr.empty() ? "" : ", ") + c.to.variable;
                    f.vr.push_back(in_vr);
                    units[from].read_real.push_back(out_vr);
                }
                if (!f.vr.empty()) feeds.push_back(std::move(f));
            }
        }
        for (Unit& u : units) {
            u.n_connected = u.read_real.size();
            u.real.assign(u.n_connected, 0.0);
            u.integer.clear();
            u.external_value.assign(u.external_vr.size(), 0.0);
        }
        probes.clear();
        values.clear();
        sums.clear();
        resolved = true;
        return true;
    }

    // Sets the units' external inputs from `in` (one fmi2SetReal per unit that has any).
    bool set_external(const ipmsm_cosim_inputs& in, const std::string& when) {
        for (Unit& u : units) {
            if (u.external_vr.empty()) continue;
            for (size_t j = 0; j < u.external_vr.size(); ++j) u.external_value[j] = in.*u.external_field[j];
            if (!check(
                    u,
                    u.fmi.fmi2SetReal(u.component, u.external_vr.data(), u.external_vr.size(), u.external_value.data()),
                    "fmi2SetReal (" + u.external_names + ")", when))
                return false;
        }
        return true;
    }
};

void logger(fmi2ComponentEnvironment env, fmi2String /*instance*/, fmi2Status status, fmi2String category,
            fmi2String message, ...) {
    auto* u = static_cast<Unit*>(env);
    if (u == nullptr) return;
    try {
        std::string text;
        if (message != nullptr) {
            va_list ap;
            va_start(ap, message);
            text = vformat(message, ap);
            va_end(ap);
        }
        if (u->pending.size() < 1000)
            u->pending.push_back({static_cast<int>(status), category != nullptr ? category : "", std::move(text)});
    } catch (...) {}
}

// file:// URI of a directory (percent-encoding all but the unreserved characters and '/').
std::string file_uri(const std::string& path) {
    static const char* hex = "0123456789ABCDEF";
    std::string uri = "file://";
    for (unsigned char ch : path) {
        if (std::isalnum(ch) || ch == '/' || ch == '-' || ch == '.' || ch == '_' || ch == '~') {
            uri += static_cast<char>(ch);
        } else {
            uri += '%';
            uri += hex[ch >> 4];
            uri += hex[ch & 15];
        }
    }
    return uri;
}

void release(Unit& u) {
    if (u.component != nullptr) {
        if (u.initialised && !u.fatal) {
            u.fmi.fmi2Terminate(u.component);
        }
        u.fmi.fmi2FreeInstance(u.component);
        u.component = nullptr;
        u.master->flush(u);
    }
    if (u.fmi.is_open()) {
        u.fmi.close();
    }
}

}  // namespace

struct ipmsm_cosim : Master {
    using Master::Master;
};

namespace {

template <class Body>
int guarded(ipmsm_cosim* m, Body&& body) noexcept {
    if (m == nullptr) return -1;
    try {
        m->error.clear();
        return body(static_cast<Master&>(*m)) ? 0 : -1;
    } catch (const std::exception& e) {
        m->error = std::string("ipmsm_cosim: ") + e.what();
    } catch (...) {
        m->error = "ipmsm_cosim: unknown exception";
    }
    return -1;
}

}  // namespace

IPMSM_COSIM_API ipmsm_cosim* ipmsm_cosim_new(const char* coupling, double h, ipmsm_cosim_log_fn log, void* user) {
    if (!(h > 0.0) || !std::isfinite(h)) return nullptr;
    try {
        return new ipmsm_cosim(coupling, h, log, user);
    } catch (...) {
        return nullptr;
    }
}

IPMSM_COSIM_API void ipmsm_cosim_free(ipmsm_cosim* m) {
    if (m == nullptr) return;
    try {
        for (auto u = m->units.rbegin(); u != m->units.rend(); ++u) release(*u);
    } catch (...) {}
    delete m;
}

IPMSM_COSIM_API const char* ipmsm_cosim_error(const ipmsm_cosim* m) {
    return m != nullptr ? m->error.c_str() : "ipmsm_cosim: NULL master";
}

IPMSM_COSIM_API int ipmsm_cosim_instantiate(ipmsm_cosim* handle, const char* role, const char* unzip_dir,
                                            const char* instance_name, int logging_on) {
    return guarded(handle, [&](Master& m) {
        Unit* found = m.unit(role, false);
        if (found == nullptr) return false;
        Unit& u = *found;
        if (u.fmi.is_open()) return m.fail("the " + u.role + " is already instantiated");
        if (unzip_dir == nullptr || instance_name == nullptr) return m.fail("ipmsm_cosim_instantiate: NULL argument");
        u.instance_name = instance_name;
        char* absolute = realpath(unzip_dir, nullptr);  // the resource URI needs an absolute path
        if (absolute == nullptr)
            return m.fail(u.model_identifier + ": the unzipped FMU folder " + unzip_dir + " does not exist");
        const std::string dir = absolute;
        std::free(absolute);
        std::string why;
        if (!fmu_binary::parse_description(dir, u.md, why)) return m.fail(u.model_identifier + ": " + why);
        if (u.md.model_identifier != u.model_identifier)
            return m.fail("the " + u.role + " must be " + u.model_identifier + ", " + dir + " holds '" +
                          u.md.model_identifier + "'");
        if (!u.fmi.open(fmu_binary::library_path(dir, u.model_identifier), why))
            return m.fail(u.model_identifier + ": " + why);
        u.callbacks.logger = logger;
        u.callbacks.allocateMemory = std::calloc;
        u.callbacks.freeMemory = std::free;
        u.callbacks.stepFinished = nullptr;
        u.callbacks.componentEnvironment = &u;
        const std::string resources = file_uri(dir + "/resources");
        u.component = u.fmi.fmi2Instantiate(instance_name, fmi2CoSimulation, u.md.guid.c_str(), resources.c_str(),
                                            &u.callbacks, fmi2False, logging_on ? fmi2True : fmi2False);
        if (u.component == nullptr) {
            std::string text = m.failure(u, "fmi2Instantiate returned NULL");
            u.fmi.close();
            return m.fail(std::move(text));
        }
        m.flush(u);
        return true;
    });
}

IPMSM_COSIM_API int ipmsm_cosim_enter_initialization(ipmsm_cosim* handle) {
    return guarded(handle, [&](Master& m) {
        if (!m.all_instantiated()) return false;
        const std::string when = " (start time 0 s)";
        for (Unit& u : m.units) {
            if (!m.check(u, u.fmi.fmi2SetupExperiment(u.component, fmi2False, 0.0, 0.0, fmi2False, 0.0),
                         "fmi2SetupExperiment", when) ||
                !m.check(u, u.fmi.fmi2EnterInitializationMode(u.component), "fmi2EnterInitializationMode", when))
                return false;
        }
        return true;
    });
}

#define IPMSM_COSIM_ACCESS(NAME, FMI, CTYPE, FMITYPE)                                                            \
    IPMSM_COSIM_API int NAME(ipmsm_cosim* handle, const char* role, size_t n, const unsigned* vr, CTYPE value) { \
        return guarded(handle, [&](Master& m) {                                                                  \
            Unit* u = m.unit(role);                                                                              \
            if (u == nullptr) return false;                                                                      \
            return m.check(*u, u->fmi.FMI(u->component, vr, n, reinterpret_cast<FMITYPE>(value)), #FMI,          \
                           m.coupled ? m.at_time() : std::string());                                             \
        });                                                                                                      \
    }
IPMSM_COSIM_ACCESS(ipmsm_cosim_set_real, fmi2SetReal, const double*, const fmi2Real*)
IPMSM_COSIM_ACCESS(ipmsm_cosim_set_integer, fmi2SetInteger, const int*, const fmi2Integer*)
IPMSM_COSIM_ACCESS(ipmsm_cosim_set_boolean, fmi2SetBoolean, const int*, const fmi2Boolean*)
IPMSM_COSIM_ACCESS(ipmsm_cosim_set_string, fmi2SetString, const char* const*, const fmi2String*)
IPMSM_COSIM_ACCESS(ipmsm_cosim_get_real, fmi2GetReal, double*, fmi2Real*)
IPMSM_COSIM_ACCESS(ipmsm_cosim_get_integer, fmi2GetInteger, int*, fmi2Integer*)
#undef IPMSM_COSIM_ACCESS

IPMSM_COSIM_API int ipmsm_cosim_initialize(ipmsm_cosim* handle, const ipmsm_cosim_inputs* start) {
    return guarded(handle, [&](Master& m) {
        if (!m.all_instantiated()) return false;
        if (m.resolved) return m.fail("ipmsm_cosim_initialize: already initialised");
        if (start == nullptr) return m.fail("ipmsm_cosim_initialize: NULL inputs");
        if (!m.resolve()) return false;
        for (size_t i = 0; i < m.units.size(); ++i) {
            Unit& u = m.units[i];
            // its external inputs, then its connected inputs from the units before it
            std::vector<fmi2ValueReference> vr = u.external_vr;
            std::vector<double> value;
            for (auto field : u.external_field) value.push_back(start->*field);
            std::string names = u.external_names;
            for (const Feed& f : m.feeds) {
                if (f.to != i || f.from >= i) continue;
                names += (vr.empty() ? "" : ", ") + f.names;
                vr.insert(vr.end(), f.vr.begin(), f.vr.end());
                const double* sent = m.units[f.from].real.data() + f.offset;
                value.insert(value.end(), sent, sent + f.vr.size());
            }
            if (!vr.empty() && !m.check(u, u.fmi.fmi2SetReal(u.component, vr.data(), vr.size(), value.data()),
                                        "fmi2SetReal (" + names + ")", ""))
                return false;
            if (!m.check(u, u.fmi.fmi2ExitInitializationMode(u.component), "fmi2ExitInitializationMode", ""))
                return false;
            u.initialised = true;
            if (u.n_connected > 0 &&
                !m.check(u, u.fmi.fmi2GetReal(u.component, u.read_real.data(), u.n_connected, u.real.data()),
                         "fmi2GetReal", ""))
                return false;
        }
        m.k = 0;
        m.coupled = true;
        return true;
    });
}

IPMSM_COSIM_API int ipmsm_cosim_probes(ipmsm_cosim* handle, size_t n, const char* const* names) {
    return guarded(handle, [&](Master& m) {
        if (!m.coupled) return m.fail("ipmsm_cosim_probes: initialise first");
        if (n > 0 && names == nullptr) return m.fail("ipmsm_cosim_probes: NULL names");
        // The read lists: the connected outputs stay in front (and keep their values).
        for (Unit& u : m.units) {
            u.read_real.resize(u.n_connected);
            u.read_int.clear();
        }
        // a variable read twice is read once (the connected outputs included)
        auto slot = [](std::vector<fmi2ValueReference>& list, fmi2ValueReference vr) {
            for (size_t s = 0; s < list.size(); ++s)
                if (list[s] == vr) return s;
            list.push_back(vr);
            return list.size() - 1;
        };
        std::vector<Probe> probes;
        for (size_t j = 0; j < n; ++j) {
            if (names[j] == nullptr) return m.fail(format("probe %zu: NULL name", j));
            const std::string name = names[j];
            if (name == "|i|" || name == "|i|^2") {
                const int p = m.coupling.unit_index("plant");
                if (p < 0) return m.fail("probe " + name + ": the coupling has no plant");
                Unit& u = m.units[static_cast<size_t>(p)];
                fmi2ValueReference d, q;
                std::string why;
                if (!u.real_vr("i_d", d, why) || !u.real_vr("i_q", q, why)) return m.fail("probe " + name + ": " + why);
                probes.push_back({name == "|i|" ? Probe::current_abs : Probe::current_sq, static_cast<size_t>(p),
                                  slot(u.read_real, d), slot(u.read_real, q)});
                continue;
            }
            const size_t dot = name.find('.');
            const int i = dot == std::string::npos ? -1 : m.coupling.unit_index(name.substr(0, dot));
            if (i < 0)
                return m.fail("probe '" + name + "': not ROLE.VARIABLE of a unit of the coupling, '|i|' or '|i|^2'");
            Unit& u = m.units[static_cast<size_t>(i)];
            const std::string var = name.substr(dot + 1);
            const auto it = u.md.vr.find(var);
            if (it == u.md.vr.end())
                return m.fail("probe '" + name + "': " + u.model_identifier + " has no variable '" + var + "'");
            const std::string type = u.type_of(var);
            if (type == "Real") {
                probes.push_back({Probe::real, static_cast<size_t>(i), slot(u.read_real, it->second), 0});
            } else if (type == "Integer" || type == "Enumeration") {
                probes.push_back({Probe::integer, static_cast<size_t>(i), slot(u.read_int, it->second), 0});
            } else {
                return m.fail("probe '" + name + "' is a " + type +
                              ": only Real and Integer variables can be averaged");
            }
        }
        for (Unit& u : m.units) {
            u.real.resize(u.read_real.size());
            u.integer.resize(u.read_int.size());
        }
        m.probes = std::move(probes);
        m.values.assign(m.probes.size(), 0.0);
        m.sums.assign(m.probes.size(), 0.0);
        return true;
    });
}

IPMSM_COSIM_API long long ipmsm_cosim_advance(ipmsm_cosim* handle, long long n_steps, const ipmsm_cosim_inputs* inputs,
                                              double* mean, double* end, double* trace, long long trace_rows,
                                              long long decimation) {
    long long rows = 0;
    const int rc = guarded(handle, [&](Master& m) {
        if (!m.coupled) return m.fail("ipmsm_cosim_advance: initialise first");
        if (m.stopped)
            return m.fail("advance: the master stopped after a failed step" + m.at_time() +
                          "; the units are out of step: close the master");
        if (n_steps < 1) return m.fail(format("ipmsm_cosim_advance: n_steps = %lld, must be >= 1", n_steps));
        if (inputs == nullptr) return m.fail("ipmsm_cosim_advance: NULL inputs");
        const size_t np = m.probes.size();
        if (np > 0 && (mean == nullptr || end == nullptr)) return m.fail("ipmsm_cosim_advance: NULL mean/end");
        if (trace != nullptr) {
            if (decimation < 1)
                return m.fail(format("ipmsm_cosim_advance: decimation = %lld, must be >= 1", decimation));
            const long long want_rows = n_steps / decimation;
            if (trace_rows < want_rows)
                return m.fail(
                    format("ipmsm_cosim_advance: the trace has %lld rows, %lld steps / decimation %lld "
                           "need %lld",
                           trace_rows, n_steps, decimation, want_rows));
        }
        // The external inputs, once (refused values: k unchanged, the master stays usable).
        if (!m.set_external(*inputs, m.at_time())) return false;

        const double h = m.h;
        const Probe* probes = m.probes.data();
        double* values = m.values.data();
        double* sums = m.sums.data();
        for (size_t j = 0; j < np; ++j) sums[j] = 0.0;
        long long next_row_step = trace != nullptr ? decimation : -1;
        auto stop = [&](Unit& u, fmi2Status s, const std::string& fn) {
            m.stopped = true;
            return m.check(u, s, fn, m.at_time());
        };
        for (long long step = 1; step <= n_steps; ++step) {
            const double t = static_cast<double>(m.k) * h;
            fmi2Status s;
            // The exchange: each connected input gets its output's value after the previous step.
            for (const Feed& f : m.feeds) {
                Unit& to = m.units[f.to];
                if ((s = to.fmi.fmi2SetReal(to.component, f.vr.data(), f.vr.size(),
                                            m.units[f.from].real.data() + f.offset)) > fmi2Warning)
                    return stop(to, s, "fmi2SetReal (" + f.names + ")");
            }
            for (Unit& u : m.units)
                if ((s = u.fmi.fmi2DoStep(u.component, t, h, fmi2True)) > fmi2Warning) return stop(u, s, "fmi2DoStep");
            ++m.k;
            for (Unit& u : m.units) {
                if ((s = u.fmi.fmi2GetReal(u.component, u.read_real.data(), u.read_real.size(), u.real.data())) >
                    fmi2Warning)
                    return stop(u, s, "fmi2GetReal");
                if (!u.read_int.empty() && (s = u.fmi.fmi2GetInteger(u.component, u.read_int.data(), u.read_int.size(),
                                                                     u.integer.data())) > fmi2Warning)
                    return stop(u, s, "fmi2GetInteger");
            }
            for (Unit& u : m.units)
                if (!u.pending.empty()) m.flush(u);
            for (size_t j = 0; j < np; ++j) {
                const Probe& pr = probes[j];
                const Unit& u = m.units[pr.unit];
                double v;
                switch (pr.kind) {
                    case Probe::real: v = u.real[pr.slot]; break;
                    case Probe::integer: v = static_cast<double>(u.integer[pr.slot]); break;
                    case Probe::current_abs: {
                        const double id = u.real[pr.slot], iq = u.real[pr.slot2];
                        v = std::sqrt(id * id + iq * iq);
                        break;
                    }
                    default: {
                        const double id = u.real[pr.slot], iq = u.real[pr.slot2];
                        v = id * id + iq * iq;
                        break;
                    }
                }
                values[j] = v;
                sums[j] += v;
            }
            if (step == next_row_step) {
                double* row = trace + rows * static_cast<long long>(np + 1);
                row[0] = static_cast<double>(m.k) * h;
                for (size_t j = 0; j < np; ++j) row[j + 1] = values[j];
                ++rows;
                next_row_step += decimation;
            }
        }
        const double n = static_cast<double>(n_steps);
        for (size_t j = 0; j < np; ++j) {
            mean[j] = sums[j] / n;
            end[j] = values[j];
        }
        return true;
    });
    return rc == 0 ? rows : -1;
}

IPMSM_COSIM_API long long ipmsm_cosim_step_index(const ipmsm_cosim* m) { return m != nullptr ? m->k : -1; }

IPMSM_COSIM_API double ipmsm_cosim_time(const ipmsm_cosim* m) {
    return m != nullptr ? static_cast<double>(m->k) * m->h : std::nan("");
}
