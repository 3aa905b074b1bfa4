// ipmsm_cosim: the native FMI 2.0 master for IpmsmController + IpmsmPlant (see cosim.h).
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

struct Unit {
    Master* master = nullptr;
    int index = 0;
    std::string model_identifier, instance_name;
    fmi2Component component = nullptr;
    fmi2CallbackFunctions callbacks{};
    bool initialised = false;  // fmi2ExitInitializationMode succeeded
    bool fatal = false;        // an fmi2Fatal: only fmi2FreeInstance is allowed
    std::vector<LogEntry> pending;  // logged during the current FMI call

    fmu_binary::Functions fmi;  // the FMU's binary, dlopened; closed with the instance

    const char* label() const { return index == 0 ? "controller" : "plant"; }
};

struct Probe {
    int unit, kind;
    unsigned vr;
    size_t slot;  // index into the unit's real or integer read buffer
};

struct Master {
    double h;
    ipmsm_cosim_log_fn log_fn;
    void* log_user;
    Unit units[2];
    std::string error;

    // coupling (ipmsm_cosim_couple)
    bool coupled = false;
    bool stopped = false;  // a step failed: the units are no longer in step
    long long k = 0;
    fmi2ValueReference c_slow[4], c_in_i[2], p_slow[3], p_in_u[2];
    // per unit, what is read after every step: Reals (the coupling outputs first), Integers
    std::vector<fmi2ValueReference> read_real[2], read_int[2];
    std::vector<double> real_buf[2];
    std::vector<fmi2Integer> int_buf[2];
    std::vector<Probe> probes;
    std::vector<double> values, sums;

    Master(double h_, ipmsm_cosim_log_fn fn, void* user) : h(h_), log_fn(fn), log_user(user) {
        for (int i = 0; i < 2; ++i) {
            units[i].master = this;
            units[i].index = i;
        }
    }

    bool fail(std::string text) {
        error = std::move(text);
        return false;
    }

    // Passes the unit's pending log messages on and clears them; all of them, or (after a
    // failed call, whose error text quotes them) only those below fmi2Warning.
    void flush(Unit& u, bool quoted = false) {
        for (const LogEntry& e : u.pending) {
            if (quoted && e.status >= fmi2Warning) continue;
            if (log_fn != nullptr) {
                log_fn(log_user, u.index, u.instance_name.c_str(), e.status, e.category.c_str(), e.message.c_str());
            } else if (e.status >= fmi2Warning) {
                std::fprintf(stderr, "[%s %s %s] %s\n", u.instance_name.c_str(),
                             status_name(static_cast<fmi2Status>(e.status)), e.category.c_str(), e.message.c_str());
            }
        }
        u.pending.clear();
    }

    // After an FMI call: true if it succeeded (fmi2OK, fmi2Warning). Otherwise the error text
    // names the FMU, the function, the time (`when`) and quotes the FMU's log of the call.
    bool check(Unit& u, fmi2Status s, const char* function, const std::string& when) {
        if (s == fmi2OK || s == fmi2Warning) {
            if (!u.pending.empty()) flush(u);
            return true;
        }
        if (s == fmi2Fatal) u.fatal = true;
        std::string text = u.model_identifier + " (" + u.label() + ", instance '" + u.instance_name + "'): " +
                           function + when + " returned " + status_name(s);
        bool any = false;
        for (const LogEntry& e : u.pending) {
            if (e.status < fmi2Warning) continue;
            text += any ? "; " : ": ";
            text += e.message;
            any = true;
        }
        if (!any) text += " (the FMU logged no message)";
        flush(u, true);
        return fail(std::move(text));
    }

    std::string at_time() const {
        return format(" at t = %.9g s (step k = %lld)", static_cast<double>(k) * h, k);
    }

    bool unit_ok(int unit, bool need_instance = true) {
        if (unit != 0 && unit != 1) return fail(format("unit %d: 0 is the controller, 1 the plant", unit));
        if (need_instance && units[unit].component == nullptr)
            return fail(std::string(unit == 0 ? "the controller" : "the plant") + " is not instantiated");
        if (need_instance && units[unit].fatal)
            return fail(units[unit].model_identifier + " reported fmi2Fatal earlier: it can only be freed");
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
    } catch (...) {
    }
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

Master* as_master(ipmsm_cosim* m) { return reinterpret_cast<Master*>(m); }

template <class Body>
int guarded(ipmsm_cosim* handle, Body&& body) noexcept {
    Master* m = as_master(handle);
    if (m == nullptr) return -1;
    try {
        m->error.clear();
        return body(*m) ? 0 : -1;
    } catch (const std::exception& e) {
        m->error = std::string("ipmsm_cosim: ") + e.what();
    } catch (...) {
        m->error = "ipmsm_cosim: unknown exception";
    }
    return -1;
}

// Builds the read lists of both units and the probes' slots.
void build_reads(Master& m, const std::vector<Probe>& requested) {
    for (int u = 0; u < 2; ++u) {
        m.read_real[u].resize(2);  // the coupling outputs stay in front
        m.read_int[u].clear();
    }
    m.probes.clear();
    for (Probe p : requested) {
        if (p.kind == IPMSM_COSIM_REAL || p.kind == IPMSM_COSIM_INTEGER) {
            auto& list = p.kind == IPMSM_COSIM_REAL ? m.read_real[p.unit] : m.read_int[p.unit];
            size_t slot = 0;
            while (slot < list.size() && list[slot] != p.vr) ++slot;
            if (slot == list.size()) list.push_back(p.vr);
            p.slot = slot;
        } else {
            p.unit = IPMSM_COSIM_PLANT;
            p.slot = 0;
        }
        m.probes.push_back(p);
    }
    for (int u = 0; u < 2; ++u) {
        m.real_buf[u].resize(m.read_real[u].size());
        m.int_buf[u].resize(m.read_int[u].size());
    }
    m.values.assign(m.probes.size(), 0.0);
    m.sums.assign(m.probes.size(), 0.0);
}

}  // namespace

struct ipmsm_cosim : Master {
    using Master::Master;
};

IPMSM_COSIM_API ipmsm_cosim* ipmsm_cosim_new(double h, ipmsm_cosim_log_fn log, void* user) {
    if (!(h > 0.0) || !std::isfinite(h)) return nullptr;
    try {
        return new ipmsm_cosim(h, log, user);
    } catch (...) {
        return nullptr;
    }
}

IPMSM_COSIM_API void ipmsm_cosim_free(ipmsm_cosim* m) {
    if (m == nullptr) return;
    try {
        release(m->units[1]);
        release(m->units[0]);
    } catch (...) {
    }
    delete m;
}

IPMSM_COSIM_API const char* ipmsm_cosim_error(const ipmsm_cosim* m) {
    return m != nullptr ? m->error.c_str() : "ipmsm_cosim: NULL master";
}

IPMSM_COSIM_API int ipmsm_cosim_instantiate(ipmsm_cosim* handle, int unit, const char* unzip_dir,
                                            const char* model_identifier, const char* guid,
                                            const char* instance_name, int logging_on) {
    return guarded(handle, [&](Master& m) {
        if (!m.unit_ok(unit, false)) return false;
        Unit& u = m.units[unit];
        if (u.fmi.is_open()) return m.fail(std::string("the ") + u.label() + " is already instantiated");
        if (unzip_dir == nullptr || model_identifier == nullptr || guid == nullptr || instance_name == nullptr)
            return m.fail("ipmsm_cosim_instantiate: NULL argument");
        u.model_identifier = model_identifier;
        u.instance_name = instance_name;
        char* absolute = realpath(unzip_dir, nullptr);  // the resource URI needs an absolute path
        if (absolute == nullptr)
            return m.fail(u.model_identifier + ": the unzipped FMU folder " + unzip_dir + " does not exist");
        const std::string dir = absolute;
        std::free(absolute);
        const std::string path = fmu_binary::library_path(dir, model_identifier);
        std::string why;
        if (!u.fmi.open(path, why)) return m.fail(u.model_identifier + ": " + why);
        u.callbacks.logger = logger;
        u.callbacks.allocateMemory = std::calloc;
        u.callbacks.freeMemory = std::free;
        u.callbacks.stepFinished = nullptr;
        u.callbacks.componentEnvironment = &u;
        const std::string resources = file_uri(dir + "/resources");
        u.component = u.fmi.fmi2Instantiate(instance_name, fmi2CoSimulation, guid, resources.c_str(), &u.callbacks,
                                    fmi2False, logging_on ? fmi2True : fmi2False);
        if (u.component == nullptr) {
            std::string text = u.model_identifier + " (" + u.label() + ", instance '" + u.instance_name +
                               "'): fmi2Instantiate returned NULL";
            bool any = false;
            for (const LogEntry& e : u.pending) {
                if (e.status < fmi2Warning) continue;
                text += (any ? "; " : ": ") + e.message;
                any = true;
            }
            m.flush(u, true);
            u.fmi.close();
            return m.fail(std::move(text));
        }
        m.flush(u);
        return true;
    });
}

IPMSM_COSIM_API int ipmsm_cosim_enter_initialization(ipmsm_cosim* handle, int unit, double start_time) {
    return guarded(handle, [&](Master& m) {
        if (!m.unit_ok(unit)) return false;
        Unit& u = m.units[unit];
        const std::string when = format(" (start time %.9g s)", start_time);
        return m.check(u, u.fmi.fmi2SetupExperiment(u.component, fmi2False, 0.0, start_time, fmi2False, 0.0),
                       "fmi2SetupExperiment", when) &&
               m.check(u, u.fmi.fmi2EnterInitializationMode(u.component), "fmi2EnterInitializationMode", when);
    });
}

IPMSM_COSIM_API int ipmsm_cosim_exit_initialization(ipmsm_cosim* handle, int unit) {
    return guarded(handle, [&](Master& m) {
        if (!m.unit_ok(unit)) return false;
        Unit& u = m.units[unit];
        if (!m.check(u, u.fmi.fmi2ExitInitializationMode(u.component), "fmi2ExitInitializationMode", "")) return false;
        u.initialised = true;
        return true;
    });
}

#define IPMSM_COSIM_ACCESS(NAME, FMI, CTYPE, FMITYPE)                                                        \
    IPMSM_COSIM_API int NAME(ipmsm_cosim* handle, int unit, size_t n, const unsigned* vr, CTYPE value) {     \
        return guarded(handle, [&](Master& m) {                                                              \
            if (!m.unit_ok(unit)) return false;                                                              \
            Unit& u = m.units[unit];                                                                         \
            return m.check(u, u.fmi.FMI(u.component, vr, n, reinterpret_cast<FMITYPE>(value)), #FMI,        \
                           m.coupled ? m.at_time() : std::string());                                         \
        });                                                                                                  \
    }
IPMSM_COSIM_ACCESS(ipmsm_cosim_set_real, fmi2SetReal, const double*, const fmi2Real*)
IPMSM_COSIM_ACCESS(ipmsm_cosim_set_integer, fmi2SetInteger, const int*, const fmi2Integer*)
IPMSM_COSIM_ACCESS(ipmsm_cosim_set_boolean, fmi2SetBoolean, const int*, const fmi2Boolean*)
IPMSM_COSIM_ACCESS(ipmsm_cosim_set_string, fmi2SetString, const char* const*, const fmi2String*)
IPMSM_COSIM_ACCESS(ipmsm_cosim_get_real, fmi2GetReal, double*, fmi2Real*)
IPMSM_COSIM_ACCESS(ipmsm_cosim_get_integer, fmi2GetInteger, int*, fmi2Integer*)
#undef IPMSM_COSIM_ACCESS

IPMSM_COSIM_API int ipmsm_cosim_couple(ipmsm_cosim* handle, const unsigned* controller_vr, const unsigned* plant_vr,
                                       long long k0) {
    return guarded(handle, [&](Master& m) {
        if (!m.unit_ok(0) || !m.unit_ok(1)) return false;
        if (!m.units[0].initialised || !m.units[1].initialised)
            return m.fail("ipmsm_cosim_couple: initialise both units first");
        if (controller_vr == nullptr || plant_vr == nullptr) return m.fail("ipmsm_cosim_couple: NULL argument");
        std::copy(controller_vr, controller_vr + 4, m.c_slow);
        std::copy(controller_vr + 4, controller_vr + 6, m.c_in_i);
        std::copy(plant_vr, plant_vr + 2, m.p_in_u);
        std::copy(plant_vr + 2, plant_vr + 5, m.p_slow);
        m.read_real[0].assign(controller_vr + 6, controller_vr + 8);
        m.read_real[1].assign(plant_vr + 5, plant_vr + 7);
        const std::vector<Probe> keep = m.probes;
        build_reads(m, keep);
        m.k = k0;
        m.stopped = false;
        m.coupled = true;
        Unit &c = m.units[0], &p = m.units[1];
        const std::string when = m.at_time();
        return m.check(p, p.fmi.fmi2GetReal(p.component, m.read_real[1].data(), 2, m.real_buf[1].data()), "fmi2GetReal",
                       when) &&
               m.check(c, c.fmi.fmi2GetReal(c.component, m.read_real[0].data(), 2, m.real_buf[0].data()), "fmi2GetReal",
                       when);
    });
}

IPMSM_COSIM_API int ipmsm_cosim_probes(ipmsm_cosim* handle, size_t n, const int* unit, const int* kind,
                                       const unsigned* vr) {
    return guarded(handle, [&](Master& m) {
        if (!m.coupled) return m.fail("ipmsm_cosim_probes: couple first");
        if (n > 0 && (unit == nullptr || kind == nullptr || vr == nullptr))
            return m.fail("ipmsm_cosim_probes: NULL argument");
        std::vector<Probe> requested;
        for (size_t i = 0; i < n; ++i) {
            if (kind[i] < IPMSM_COSIM_REAL || kind[i] > IPMSM_COSIM_CURRENT_SQ)
                return m.fail(format("probe %zu: unknown kind %d", i, kind[i]));
            if (unit[i] != 0 && unit[i] != 1) return m.fail(format("probe %zu: unknown unit %d", i, unit[i]));
            requested.push_back({unit[i], kind[i], vr[i], 0});
        }
        // Keep the current coupling outputs (the buffers are resized, the front two kept).
        const double c0 = m.real_buf[0][0], c1 = m.real_buf[0][1], p0 = m.real_buf[1][0], p1 = m.real_buf[1][1];
        build_reads(m, requested);
        m.real_buf[0][0] = c0;
        m.real_buf[0][1] = c1;
        m.real_buf[1][0] = p0;
        m.real_buf[1][1] = p1;
        return true;
    });
}

IPMSM_COSIM_API long long ipmsm_cosim_advance(ipmsm_cosim* handle, long long n_steps, const double* slow,
                                              double* mean, double* end, double* trace, long long trace_rows,
                                              long long decimation) {
    long long rows = 0;
    const int rc = guarded(handle, [&](Master& m) {
        if (!m.coupled) return m.fail("ipmsm_cosim_advance: couple first");
        if (m.stopped)
            return m.fail("advance: the master stopped after a failed step" + m.at_time() +
                          "; the units are out of step: close the master");
        if (n_steps < 1) return m.fail(format("ipmsm_cosim_advance: n_steps = %lld, must be >= 1", n_steps));
        if (slow == nullptr) return m.fail("ipmsm_cosim_advance: NULL slow inputs");
        const size_t np = m.probes.size();
        if (np > 0 && (mean == nullptr || end == nullptr)) return m.fail("ipmsm_cosim_advance: NULL mean/end");
        long long want_rows = 0;
        if (trace != nullptr) {
            if (decimation < 1) return m.fail(format("ipmsm_cosim_advance: decimation = %lld, must be >= 1", decimation));
            want_rows = n_steps / decimation;
            if (trace_rows < want_rows)
                return m.fail(format("ipmsm_cosim_advance: the trace has %lld rows, %lld steps / decimation %lld "
                                     "need %lld", trace_rows, n_steps, decimation, want_rows));
        }
        Unit &c = m.units[0], &p = m.units[1];
        // The slow inputs, once (refused values change nothing: the master stays usable).
        const double c_slow[4] = {slow[0], slow[1], slow[2], slow[3]};
        const double p_slow[3] = {slow[1], slow[3], slow[4]};
        {
            const std::string when = m.at_time();
            if (!m.check(c, c.fmi.fmi2SetReal(c.component, m.c_slow, 4, c_slow), "fmi2SetReal (T_ref, w_m, u_dc, T_magnet)",
                         when) ||
                !m.check(p, p.fmi.fmi2SetReal(p.component, m.p_slow, 3, p_slow), "fmi2SetReal (w_m, T_magnet, T_winding)",
                         when))
                return false;
        }
        const fmi2Component cc = c.component, pc = p.component;
        fmi2SetRealTYPE *c_set = c.fmi.fmi2SetReal, *p_set = p.fmi.fmi2SetReal;
        fmi2DoStepTYPE *c_step = c.fmi.fmi2DoStep, *p_step = p.fmi.fmi2DoStep;
        fmi2GetRealTYPE *c_get = c.fmi.fmi2GetReal, *p_get = p.fmi.fmi2GetReal;
        fmi2GetIntegerTYPE *c_geti = c.fmi.fmi2GetInteger, *p_geti = p.fmi.fmi2GetInteger;
        double* c_real = m.real_buf[0].data();
        double* p_real = m.real_buf[1].data();
        fmi2Integer* c_int = m.int_buf[0].data();
        fmi2Integer* p_int = m.int_buf[1].data();
        const fmi2ValueReference *c_rvr = m.read_real[0].data(), *p_rvr = m.read_real[1].data();
        const fmi2ValueReference *c_ivr = m.read_int[0].data(), *p_ivr = m.read_int[1].data();
        const size_t c_nr = m.read_real[0].size(), p_nr = m.read_real[1].size();
        const size_t c_ni = m.read_int[0].size(), p_ni = m.read_int[1].size();
        const Probe* probes = m.probes.data();
        double* values = m.values.data();
        double* sums = m.sums.data();
        for (size_t j = 0; j < np; ++j) sums[j] = 0.0;
        const double h = m.h;
        long long next_row_step = trace != nullptr ? decimation : -1;

        auto stop = [&](Unit& u, fmi2Status s, const char* fn) {
            m.stopped = true;
            return m.check(u, s, fn, m.at_time());
        };
        for (long long step = 1; step <= n_steps; ++step) {
            const double t = static_cast<double>(m.k) * h;
            fmi2Status s;
            // The exchange: the plant gets the controller's voltage of the previous step (c_real[0..1]),
            // the controller the plant's current at t (p_real[0..1]).
            if ((s = p_set(pc, m.p_in_u, 2, c_real)) > fmi2Warning) return stop(p, s, "fmi2SetReal (u_d, u_q)");
            if ((s = c_set(cc, m.c_in_i, 2, p_real)) > fmi2Warning) return stop(c, s, "fmi2SetReal (i_d, i_q)");
            if ((s = p_step(pc, t, h, fmi2True)) > fmi2Warning) return stop(p, s, "fmi2DoStep");
            if ((s = c_step(cc, t, h, fmi2True)) > fmi2Warning) return stop(c, s, "fmi2DoStep");
            ++m.k;
            if ((s = p_get(pc, p_rvr, p_nr, p_real)) > fmi2Warning) return stop(p, s, "fmi2GetReal");
            if ((s = c_get(cc, c_rvr, c_nr, c_real)) > fmi2Warning) return stop(c, s, "fmi2GetReal");
            if (p_ni > 0 && (s = p_geti(pc, p_ivr, p_ni, p_int)) > fmi2Warning) return stop(p, s, "fmi2GetInteger");
            if (c_ni > 0 && (s = c_geti(cc, c_ivr, c_ni, c_int)) > fmi2Warning) return stop(c, s, "fmi2GetInteger");
            if (!p.pending.empty()) m.flush(p);
            if (!c.pending.empty()) m.flush(c);
            const double id = p_real[0], iq = p_real[1];
            for (size_t j = 0; j < np; ++j) {
                const Probe& pr = probes[j];
                double v;
                switch (pr.kind) {
                    case IPMSM_COSIM_REAL: v = m.real_buf[pr.unit][pr.slot]; break;
                    case IPMSM_COSIM_INTEGER: v = static_cast<double>(pr.unit == 0 ? c_int[pr.slot] : p_int[pr.slot]); break;
                    case IPMSM_COSIM_CURRENT_ABS: v = std::sqrt(id * id + iq * iq); break;
                    default: v = id * id + iq * iq; break;
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
