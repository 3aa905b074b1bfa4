// fmu_fuzz: random FMI 2.0 call sequences against an FMU's binary, with an oracle (issue 5).
//
// It dlopens <unzipped fmu>/binaries/linux64/<modelIdentifier>.so, reads the variables from the
// modelDescription.xml, and runs seeded random sequences of every FMI 2.0 co-simulation call:
// right and wrong states, valid and unknown value references, wrong types, NULL arrays and zero
// lengths, hostile values (NaN, +-Inf, 1e300, denormals, out of range), hostile step sizes,
// flux maps good, bad and missing, resource locations NULL and odd, loggers NULL, FMU states
// got, set, freed twice, serialised, corrupted, passed to the wrong instance. No Python in the
// process: under AddressSanitizer/UBSan or valgrind every report is the FMU's.
//
// The oracle (a violation is counted and printed with the sequence's last calls):
// - every status is OK, Warning, Discard or Error (Fatal only if memory ran out: never here);
// - a call the FMI 2.0 state machine does not allow in the current state returns fmi2Error;
// - a call that returns fmi2Error changes nothing: every variable reads as before (and the
//   instance is still in its state: later calls are judged with it);
// - calls that cannot fail do not (Get with valid arguments, enter/terminate/reset in their
//   state, fmi2GetFMUstate, fmi2FreeFMUstate, fmi2SetFMUstate of one's own state, NULL/0 arrays);
// - after a successful fmi2DoStep every Real output is finite;
// - fmi2SetFMUstate of a state (also after serialising and deserialising it) restores every
//   variable bit for bit; corrupted serialised states are refused;
// - fmi2Instantiate refuses (NULL) a wrong GUID, Model Exchange, a NULL or empty name.
// With --threads it also runs instances in parallel threads and compares them bit for bit with
// a sequential run.
//
// Usage: fmu_fuzz <unzipped fmu dir> [--sequences N] [--calls M] [--seed S] [--skip NAME]...
//                 [--threads] [--verbose]
// Exit status 0 if no violation. Reproduce one sequence with --seed <its seed> --sequences 1.
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <chrono>
#include <cinttypes>
#include <climits>
#include <cmath>
#include <cstdarg>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <deque>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <sstream>
#include <string>
#include <thread>
#include <vector>

#include "fmi2Functions.h"
#include "fmu_binary.hpp"

namespace {

// --- the model description (a minimal reader for what the generator writes) ---
struct Var {
    std::string name;
    fmi2ValueReference vr = 0;
    char type = 'R';  // R I B S
    std::string causality, variability, start;
    double min = -INFINITY, max = INFINITY;
    bool computed() const { return causality == "output" || causality == "local"; }
};

struct ModelInfo {
    std::string id, guid;
    std::vector<Var> vars;
};

std::string attr(const std::string& tag, const char* name) {
    const std::string key = std::string(" ") + name + "=\"";
    const auto at = tag.find(key);
    if (at == std::string::npos) return "";
    const auto from = at + key.size();
    return tag.substr(from, tag.find('"', from) - from);
}

// The FMI type names, by the fuzzer's kind index 0..3.
constexpr const char* kTypeName[] = {"Real", "Integer", "Boolean", "String"};

ModelInfo read_model_description(const std::string& path) {
    std::ifstream f(path);
    if (!f) {
        std::fprintf(stderr, "cannot read %s\n", path.c_str());
        std::exit(2);
    }
    std::stringstream ss;
    ss << f.rdbuf();
    const std::string xml = ss.str();
    ModelInfo m;
    m.guid = attr(xml.substr(0, xml.find("<CoSimulation")), "guid");
    const auto cs = xml.find("<CoSimulation");
    m.id = attr(xml.substr(cs, xml.find('>', cs) - cs), "modelIdentifier");
    for (std::size_t at = xml.find("<ScalarVariable"); at != std::string::npos;
         at = xml.find("<ScalarVariable", at + 1)) {
        const std::string head = xml.substr(at, xml.find('>', at) - at);
        const auto end = xml.find("</ScalarVariable>", at);
        const std::string body = xml.substr(at, end - at);
        Var v;
        v.name = attr(head, "name");
        v.vr = static_cast<fmi2ValueReference>(std::stoul(attr(head, "valueReference")));
        v.causality = attr(head, "causality");
        v.variability = attr(head, "variability");
        for (const char* t : kTypeName) {
            const auto p = body.find(std::string("<") + t);
            if (p == std::string::npos) continue;
            const std::string tag = body.substr(p, body.find('>', p) - p);
            v.type = t[0];
            v.start = attr(tag, "start");
            if (!attr(tag, "min").empty()) v.min = std::stod(attr(tag, "min"));
            if (!attr(tag, "max").empty()) v.max = std::stod(attr(tag, "max"));
            break;
        }
        m.vars.push_back(v);
    }
    if (m.id.empty() || m.guid.empty() || m.vars.empty()) {
        std::fprintf(stderr, "%s: no modelIdentifier, guid or variables\n", path.c_str());
        std::exit(2);
    }
    return m;
}

// --- the FMU's functions (every FMI 2.0 co-simulation function, dlopened) ---
using Api = fmu_binary::Functions;

// --- logging: checked, counted, printed with --verbose ---
std::atomic<long> log_messages{0}, log_violations{0};
bool verbose = false;

void logger(fmi2ComponentEnvironment, fmi2String instance, fmi2Status status, fmi2String category, fmi2String message,
            ...) {
    ++log_messages;
    if (instance == nullptr || category == nullptr || message == nullptr || status < fmi2OK || status > fmi2Pending) {
        ++log_violations;
        return;
    }
    char buf[8192];
    va_list ap;
    va_start(ap, message);
    std::vsnprintf(buf, sizeof buf, message, ap);  // the glue doubles every '%': safe as a format
    va_end(ap);
    if (verbose) std::printf("    [log %s %d] %s\n", category, static_cast<int>(status), buf);
}

const char* status_name(int s) {
    static const char* names[] = {"OK", "Warning", "Discard", "Error", "Fatal", "Pending"};
    return s >= 0 && s <= 5 ? names[s] : "INVALID";
}

// --- the state machine the FMU must follow (FMI 2.0, 4.2.4) ---
enum class Phase { none, instantiated, init, step_complete, terminated };
const char* phase_name(Phase p) {
    switch (p) {
        case Phase::none: return "none";
        case Phase::instantiated: return "instantiated";
        case Phase::init: return "initializationMode";
        case Phase::step_complete: return "stepComplete";
        case Phase::terminated: return "terminated";
    }
    return "?";
}

// What every variable reads now: (status, bits) per variable, in each type's getter.
struct Snapshot {
    std::vector<std::pair<int, std::uint64_t>> v;
    bool operator==(const Snapshot& o) const { return v == o.v; }
};

std::uint64_t bits(double x) {
    std::uint64_t b;
    std::memcpy(&b, &x, sizeof b);
    return b;
}

std::uint64_t hash_string(const char* s) {
    if (s == nullptr) return 0xdeadbeefull;
    std::uint64_t h = 1469598103934665603ull;
    for (; *s; ++s) h = (h ^ static_cast<unsigned char>(*s)) * 1099511628211ull;
    return h;
}

// fmi2Instantiate's resource location of an FMU unpacked in dir.
std::string resource_uri(const std::string& dir) { return "file://" + dir + "/resources"; }

struct Options {
    std::string dir;
    long sequences = 1000;
    int calls = 40;
    std::uint64_t seed = 1;
    std::set<std::string> skip;
    bool threads = false;
};

class Fuzzer {
public:
    Fuzzer(const Api& api, const ModelInfo& m, const Options& o) : f_(api), m_(m), o_(o) {
        make_files();
        resource_uri_ = resource_uri(o.dir);
        for (const auto& v : m_.vars) {
            if (v.type == 'R' && v.computed()) real_outputs_.push_back(v.vr);
            if (v.name == "flux_map") flux_map_vr_ = static_cast<long>(v.vr);
        }
    }

    ~Fuzzer() { std::filesystem::remove_all(tmp_); }
    Fuzzer(const Fuzzer&) = delete;
    Fuzzer& operator=(const Fuzzer&) = delete;

    long violations = 0, calls = 0;
    std::array<long, 6> statuses{};
    std::map<std::string, std::array<long, 6>> per_function;  // statuses of each function
    std::map<std::string, double> seconds;                    // and the time spent in it

    void run_sequence(std::uint64_t seed) {
        rng_.seed(seed);
        seed_ = seed;
        trace_.clear();
        phase_ = Phase::none;
        c_ = nullptr;
        t_ = 0.0;
        states_.clear();
        freed_states_.clear();
        blobs_.clear();
        instantiate();
        for (int i = 0; i < o_.calls; ++i) {
            if (c_ == nullptr) {
                if (pick(4) == 0) break;
                instantiate();
                continue;
            }
            one_call();
        }
        if (c_ != nullptr) {
            note("fmi2FreeInstance (end)");
            f_.fmi2FreeInstance(c_);  // with any FMU states still alive: the FMU frees them
        }
        if (other_ != nullptr) {
            f_.fmi2FreeInstance(other_);
            other_ = nullptr;
        }
    }

private:
    // --- files the sequences use ---
    void make_files() {
        static const char kGarbage[] = "\x00\xff\xfe garbage\n";
        char tmpl[] = "/tmp/fmu_fuzz_XXXXXX";
        const char* d = mkdtemp(tmpl);
        if (d == nullptr) std::exit(2);
        tmp_ = d;
        std::ostringstream lin;  // a 9 x 9 linear map: fast to load (most sequences use it)
        lin << "# fuzz: linear machine\n# pole_pairs: 4\ni_d,i_q,psi_d,psi_q\n";
        for (int j = 0; j < 9; ++j)
            for (int k = 0; k < 9; ++k) {
                const double id = -500 + 125.0 * j, iq = -500 + 125.0 * k;
                lin << id << "," << iq << "," << 0.08 + 0.25e-3 * id << "," << 0.6e-3 * iq << "\n";
            }
        good_map_ = write("linear 9x9.csv", lin.str());
        std::string grid = "i_d,i_q,psi_d,psi_q\n";
        for (int j = 0; j < 4; ++j)
            for (int k = 0; k < 4; ++k)
                grid += std::to_string(j) + "," + std::to_string(k) + "," + std::to_string(0.1 + j * 0.01) + "," +
                        std::to_string(k * 0.01) + "\n";
        std::string folded = grid;  // psi_d falls with i_d somewhere
        folded.replace(folded.find("0.120000"), 8, "0.000000");
        bad_maps_ = {
            write("empty.csv", ""),
            write("header only.csv", "# nothing\ni_d,i_q,psi_d,psi_q\n"),
            write("text.csv", "i_d,i_q,psi_d,psi_q\n0,0,abc,0\n"),
            write("holes.csv", grid.substr(0, grid.rfind('\n', grid.size() - 2) + 1)),
            write("duplicate.csv", grid + "3,3,0.13,0.03\n"),
            write("folded.csv", folded),
            write("nan.csv", "i_d,i_q,psi_d,psi_q\n0,0,nan,0\n"),
            write("binary.csv", std::string(kGarbage, sizeof kGarbage - 1)),
            tmp_ + "/missing.csv",
            tmp_,  // a directory
            std::string(5000, 'x'),
            // issue 16: what must be refused at once and without a large allocation
            "/dev/zero",
            fifo("map.fifo"),
            write("distinct rows.csv", distinct_rows(2000)),  // 4e6 grid points if allocated first
            write("long line.csv", "i_d,i_q,psi_d,psi_q\n" + std::string(20000, '1') + ",0,0,0\n"),
            write("cr only bad.csv", "# x\ri_d,i_q,psi_d,psi_q\r0,0,\xe9,0\r"),
            write("caf\xe9 latin1.csv", "i_d,i_q,psi_d,psi_q\n\xff\xfe,0,0,0\n"),
        };
    }

    static std::string distinct_rows(int n) {
        std::string t = "i_d,i_q,psi_d,psi_q\n";
        for (int k = 0; k < n; ++k)
            t += std::to_string(k) + "," + std::to_string(k) + "," + std::to_string(0.08 + 1e-5 * k) + "," +
                 std::to_string(1e-5 * k) + "\n";
        return t;
    }

    std::string fifo(const std::string& name) {
        const std::string path = tmp_ + "/" + name;
        if (::mkfifo(path.c_str(), 0600) != 0) std::exit(2);
        return path;
    }

    std::string write(const std::string& name, const std::string& text) {
        const std::string path = tmp_ + "/" + name;
        std::ofstream(path, std::ios::binary) << text;
        return path;
    }

    // --- randomness ---
    int pick(int n) { return std::uniform_int_distribution<int>(0, n - 1)(rng_); }
    bool chance(double p) { return std::uniform_real_distribution<double>(0, 1)(rng_) < p; }
    double uniform(double a, double b) { return std::uniform_real_distribution<double>(a, b)(rng_); }

    const Var* random_var(char type, bool settable_only = false) {
        std::vector<const Var*> c;
        for (const auto& v : m_.vars)
            if (v.type == type && !o_.skip.count(v.name) && (!settable_only || !v.computed())) c.push_back(&v);
        return c.empty() ? nullptr : c[pick(static_cast<int>(c.size()))];
    }

    double real_value(const Var& v) {
        const double s = v.start.empty() ? 1.0 : std::atof(v.start.c_str());
        const double hostile[] = {NAN, INFINITY, -INFINITY, 1e300, -1e300, 5e-324, -0.0, 1e-300};
        switch (pick(10)) {
            case 0: return hostile[pick(8)];
            case 1: return std::isfinite(v.min) ? v.min : -1e6;
            case 2: return std::isfinite(v.max) ? v.max : 1e6;
            case 3: return std::isfinite(v.min) ? v.min - 1.0 : 0.0;
            case 4: return std::isfinite(v.max) ? v.max + 1.0 : -s;
            case 5: return 0.0;
            default: return s + uniform(-2.0, 2.0) * (std::abs(s) + 1.0);
        }
    }

    int int_value(const Var& v) {
        const int s = v.start.empty() ? 0 : std::atoi(v.start.c_str());
        switch (pick(8)) {
            case 0: return INT_MIN;
            case 1: return INT_MAX;
            case 2: return std::isfinite(v.min) ? static_cast<int>(v.min) : -1;
            case 3: return std::isfinite(v.max) ? static_cast<int>(v.max) : 7;
            case 4: return std::isfinite(v.min) ? static_cast<int>(v.min) - 1 : 0;
            default: return s + pick(5) - 2;
        }
    }

    std::string string_value() {
        switch (pick(6)) {
            case 0: return "";
            case 1:
            case 2:
            case 3: return good_map_;
            default: return bad_maps_[pick(static_cast<int>(bad_maps_.size()))];
        }
    }

    // --- bookkeeping ---
    void start_clock() { last_ = std::chrono::steady_clock::now(); }
    void note(const std::string& s) {
        trace_.push_back(s);
        if (trace_.size() > 40) trace_.pop_front();
        if (verbose) std::printf("  %s\n", s.c_str());
    }

    void violation(const std::string& what) {
        ++violations;
        if (violations > 20) return;
        std::printf("VIOLATION (seed %" PRIu64 ", state %s): %s\n  last calls:\n", seed_, phase_name(phase_),
                    what.c_str());
        for (const auto& s : trace_) std::printf("    %s\n", s.c_str());
    }

    int status(const std::string& call, int s) {
        ++calls;
        note(call + " -> " + status_name(s));
        if (s < 0 || s > 5)
            violation(call + " returned " + std::to_string(s));
        else {
            ++statuses[s];
            const std::string fn = call.substr(0, call.find_first_of("( "));
            ++per_function[fn][s];
            const auto now = std::chrono::steady_clock::now();
            seconds[fn] += std::chrono::duration<double>(now - last_).count();
        }
        if (s == fmi2Fatal || s == fmi2Pending) violation(call + " returned " + status_name(s));
        return s;
    }

    Snapshot snapshot(fmi2Component c) {
        Snapshot snap;
        for (const auto& v : m_.vars) {
            const fmi2ValueReference vr = v.vr;
            int s = 0;
            std::uint64_t b = 0;
            if (v.type == 'R') {
                double x = 0;
                s = f_.fmi2GetReal(c, &vr, 1, &x);
                b = bits(x);
            } else if (v.type == 'I' || v.type == 'B') {
                fmi2Integer x = 0;
                s = v.type == 'I' ? f_.fmi2GetInteger(c, &vr, 1, &x) : f_.fmi2GetBoolean(c, &vr, 1, &x);
                b = static_cast<std::uint64_t>(x);
            } else {
                fmi2String x = nullptr;
                s = f_.fmi2GetString(c, &vr, 1, &x);
                b = hash_string(s == fmi2OK ? x : nullptr);
            }
            snap.v.emplace_back(s, s == fmi2OK ? b : 0);
        }
        return snap;
    }

    bool allowed(const std::string& fn) const {
        const Phase p = phase_;
        const bool get = p == Phase::init || p == Phase::step_complete || p == Phase::terminated;
        const bool set = p == Phase::instantiated || p == Phase::init || p == Phase::step_complete;
        if (fn == "setup" || fn == "enter") return p == Phase::instantiated;
        if (fn == "exit") return p == Phase::init;
        if (fn == "terminate" || fn == "doStep") return p == Phase::step_complete;
        if (fn == "get") return get;
        if (fn == "set") return set;
        if (fn == "status") return p == Phase::step_complete || p == Phase::terminated;
        return true;
    }

    // A call that may change the instance: if it returns Error, nothing may have changed.
    template <class F>
    int mutating(const std::string& call, const std::string& fn, F&& f) {
        const Snapshot before = snapshot(c_);
        const Phase phase_before = phase_;
        start_clock();
        const int s = status(call, f());
        if (!allowed(fn) && s != fmi2Error)
            violation(call + " is not allowed in state " + phase_name(phase_) + " but returned " + status_name(s));
        if (s == fmi2Error) {
            if (!(snapshot(c_) == before)) violation(call + " returned Error but changed variables");
            phase_ = phase_before;
        }
        return s;
    }

    void check_outputs_finite(const std::string& after) {
        for (fmi2ValueReference vr : real_outputs_) {
            double x = 0;
            const int s = f_.fmi2GetReal(c_, &vr, 1, &x);
            if (s != fmi2OK || !std::isfinite(x))
                violation("after " + after + ": output vr " + std::to_string(vr) + " reads " + status_name(s) + " " +
                          std::to_string(x));
        }
    }

    // --- the calls ---
    void instantiate() {
        cb_.logger = logger;
        cb_no_logger_.logger = nullptr;
        std::string name = "fuzz" + std::to_string(pick(3)), guid = m_.guid;
        const char* uri = resource_uri_.c_str();
        bool valid = true;
        const fmi2CallbackFunctions* callbacks = &cb_;
        int type = fmi2CoSimulation;
        switch (pick(16)) {
            case 0:
                valid = false;
                guid = "{00000000-0000-0000-0000-000000000000}";
                break;
            case 1:
                valid = false;
                type = fmi2ModelExchange;
                break;
            case 2:
                valid = false;
                name = "";
                break;
            case 3: callbacks = nullptr; break;
            case 4: callbacks = &cb_no_logger_; break;
            case 5: uri = nullptr; break;
            case 6: uri = "http://example.invalid/resources"; break;
            case 7: uri = "file:///nonexistent%20dir/resources"; break;
            default: break;
        }
        const fmi2Component c = f_.fmi2Instantiate(name.c_str(), static_cast<fmi2Type>(type), guid.c_str(), uri,
                                                   callbacks, fmi2False, pick(2) ? fmi2True : fmi2False);
        ++calls;
        note("fmi2Instantiate(" + std::string(valid ? "valid" : "invalid") + ") -> " + (c ? "instance" : "NULL"));
        if (valid != (c != nullptr))
            violation(std::string("fmi2Instantiate ") + (valid ? "refused valid" : "accepted invalid") + " arguments");
        c_ = c;
        phase_ = c ? Phase::instantiated : Phase::none;
        t_ = 0.0;
        if (c_) small_map();
        if (c_ && chance(0.05) && other_ == nullptr)  // a second instance, for foreign FMU states
            other_ = f_.fmi2Instantiate("other", fmi2CoSimulation, m_.guid.c_str(), resource_uri_.c_str(), &cb_,
                                        fmi2False, fmi2False);
    }

    // Mostly the small map (fast initialisation), also after a reset; else the default map.
    void small_map() {
        if (flux_map_vr_ < 0 || !chance(0.95)) return;
        const fmi2ValueReference vr = static_cast<fmi2ValueReference>(flux_map_vr_);
        const char* p = good_map_.c_str();
        status("fmi2SetString(flux_map = small map)", f_.fmi2SetString(c_, &vr, 1, &p));
    }

    void one_call() {
        start_clock();
        // Three calls in four are ones that move the instance on in its present state (so that
        // sequences get deep); the fourth is any call at all.
        if (chance(0.75)) {
            const int w = pick(100);
            switch (phase_) {
                case Phase::instantiated:
                    if (w < 20) return setup();
                    if (w < 70) return enter();
                    return set_values();
                case Phase::init:
                    if (w < 35) return set_values();
                    if (w < 85) return exit_init();
                    return get_values();
                case Phase::step_complete:
                    if (w < 55) return do_step();
                    if (w < 75) return set_values();
                    if (w < 85) return get_values();
                    if (w < 95) return fmu_state();
                    if (w < 98) return terminate();
                    return reset();
                default:
                    if (w < 40) return reset();
                    if (w < 60) return get_values();
                    if (w < 80) return fmu_state();
                    return free_instance();
            }
        }
        const int op = pick(100);
        if (op < 6)
            setup();
        else if (op < 14)
            enter();
        else if (op < 24)
            exit_init();
        else if (op < 44)
            do_step();
        else if (op < 56)
            set_values();
        else if (op < 66)
            get_values();
        else if (op < 70)
            terminate();
        else if (op < 73)
            reset();
        else if (op < 75)
            free_instance();
        else if (op < 90)
            fmu_state();
        else if (op < 94)
            status_queries();
        else if (op < 96)
            debug_logging();
        else
            unsupported();
    }

    void setup() {
        const double starts[] = {0.0, 0.0, 1.5, -2.0, NAN, INFINITY, 1e300};
        const double start = starts[pick(7)];
        const bool stop_defined = chance(0.3);
        const double stop = stop_defined ? (chance(0.5) ? start + 1.0 : start - 1.0) : 0.0;
        const int s = mutating("fmi2SetupExperiment(start " + std::to_string(start) + ")", "setup", [&] {
            return f_.fmi2SetupExperiment(c_, chance(0.5), 1e-6, start, stop_defined, stop);
        });
        if (s == fmi2OK) t_ = start;
        if (allowed("setup") && std::isfinite(start) && !stop_defined && s != fmi2OK)
            violation("a valid fmi2SetupExperiment failed");
    }

    void enter() {
        const bool ok_expected = allowed("enter");
        const int s =
            mutating("fmi2EnterInitializationMode", "enter", [&] { return f_.fmi2EnterInitializationMode(c_); });
        if (ok_expected && s != fmi2OK) violation("fmi2EnterInitializationMode failed in state instantiated");
        if (s == fmi2OK) phase_ = Phase::init;
    }

    void exit_init() {
        const int s = mutating("fmi2ExitInitializationMode", "exit", [&] { return f_.fmi2ExitInitializationMode(c_); });
        if (s == fmi2OK || s == fmi2Warning) {
            phase_ = Phase::step_complete;
            check_outputs_finite("fmi2ExitInitializationMode");
        }
    }

    void do_step() {
        const double hs[] = {1e-4, 1e-4, 1e-4, 1e-5, 1e-3, 1e-2, 1.0, 0.0, -1e-4, NAN, INFINITY, 1e-12};
        const double h = hs[pick(12)];
        double t = t_;
        if (chance(0.05)) t = t_ + 1.0;  // not where the last step ended
        if (chance(0.02)) t = NAN;
        std::ostringstream call;
        call << "fmi2DoStep(t " << t << ", h " << h << ")";
        const int s = mutating(call.str(), "doStep", [&] { return f_.fmi2DoStep(c_, t, h, fmi2True); });
        if (s == fmi2OK || s == fmi2Warning) {
            if (!(h > 0) || !std::isfinite(h) || !(t == t_)) violation(call.str() + " accepted a bad step");
            t_ += h;
            check_outputs_finite(call.str());
        }
    }

    void set_values() {
        const int kind = pick(4);
        const char type = kTypeName[kind][0];
        const int n = chance(0.1) ? 0 : (chance(0.7) ? 1 : 2 + pick(3));
        std::vector<fmi2ValueReference> vr(n);
        std::vector<double> rv(n);
        std::vector<fmi2Integer> iv(n);
        std::vector<std::string> sv(n);
        std::vector<fmi2String> sp(n);
        std::ostringstream call;
        call << "fmi2Set" << kTypeName[kind] << "(";
        for (int i = 0; i < n; ++i) {
            const Var* v = random_var(type, chance(0.9));
            const int r = pick(20);
            if (v == nullptr || r == 0)
                vr[i] = r == 0 && chance(0.5) ? 0xffffffffu : static_cast<fmi2ValueReference>(m_.vars.size());
            else if (r == 1)
                vr[i] = m_.vars[pick(static_cast<int>(m_.vars.size()))].vr;  // maybe another type
            else
                vr[i] = v->vr;
            const Var& info = vr[i] < m_.vars.size() ? m_.vars[vr[i]] : m_.vars[0];
            if (type == 'R')
                rv[i] = real_value(info);
            else if (type == 'I')
                iv[i] = int_value(info);
            else if (type == 'B')
                iv[i] = pick(4) - 1;
            else {
                sv[i] = string_value();
                sp[i] = (chance(0.05)) ? nullptr : sv[i].c_str();
            }
            call << (i ? ", " : "") << vr[i] << "=";
            if (type == 'R')
                call << rv[i];
            else if (type == 'S')
                call << (sp[i] ? "\"" + sv[i].substr(0, 60) + "\"" : "NULL");
            else
                call << iv[i];
        }
        call << ")";
        const bool null_vr = n > 0 && chance(0.03), null_values = n > 0 && chance(0.03);
        const fmi2ValueReference* vrp = (null_vr || n == 0) ? nullptr : vr.data();
        mutating(call.str() + (null_vr ? " vr=NULL" : "") + (null_values ? " value=NULL" : ""), "set", [&]() -> int {
            switch (kind) {
                case 0: return f_.fmi2SetReal(c_, vrp, n, null_values || n == 0 ? nullptr : rv.data());
                case 1: return f_.fmi2SetInteger(c_, vrp, n, null_values || n == 0 ? nullptr : iv.data());
                case 2: return f_.fmi2SetBoolean(c_, vrp, n, null_values || n == 0 ? nullptr : iv.data());
                default: return f_.fmi2SetString(c_, vrp, n, null_values || n == 0 ? nullptr : sp.data());
            }
        });
    }

    void get_values() {
        const int kind = pick(4);
        const char type = kTypeName[kind][0];
        const Var* v = random_var(type);
        const int mode = pick(12);  // 0: n = 0 with NULLs, 1: NULL vr, 2: NULL value, 3: unknown vr, 4: wrong type
        fmi2ValueReference vr = v ? v->vr : 0;
        if (mode == 3) vr = static_cast<fmi2ValueReference>(m_.vars.size() + pick(3));
        if (mode == 4) vr = m_.vars[pick(static_cast<int>(m_.vars.size()))].vr;
        const std::size_t n = mode == 0 ? 0 : 1;
        double r = 0;
        fmi2Integer i = 0;
        fmi2String s = nullptr;
        const fmi2ValueReference* vrp = (mode == 0 || mode == 1) ? nullptr : &vr;
        const bool null_value = mode == 0 || mode == 2;
        const std::string call = std::string("fmi2Get") + kTypeName[kind] + "(vr " + std::to_string(vr) + ", mode " +
                                 std::to_string(mode) + ")";
        int st = 0;
        switch (kind) {
            case 0: st = f_.fmi2GetReal(c_, vrp, n, null_value ? nullptr : &r); break;
            case 1: st = f_.fmi2GetInteger(c_, vrp, n, null_value ? nullptr : &i); break;
            case 2: st = f_.fmi2GetBoolean(c_, vrp, n, null_value ? nullptr : &i); break;
            default: st = f_.fmi2GetString(c_, vrp, n, null_value ? nullptr : &s); break;
        }
        status(call, st);
        if (!allowed("get") && st != fmi2Error) violation(call + " not allowed but returned " + status_name(st));
        if (allowed("get") && mode == 0 && st != fmi2OK) violation(call + ": nvr = 0 must succeed");
        if (allowed("get") && (mode == 1 || mode == 2 || mode == 3) && st != fmi2Error)
            violation(call + ": must be refused");
        const bool right_type = vr < m_.vars.size() && m_.vars[vr].type == type;
        if (allowed("get") && mode == 4 && !right_type && st != fmi2Error)
            violation(call + ": wrong type must be refused");
        // valid arguments: must succeed (outputs in Initialization Mode may fail: their initial
        // values need a valid set of parameters)
        const bool computed_in_init = phase_ == Phase::init && vr < m_.vars.size() && m_.vars[vr].computed();
        if (allowed("get") && mode > 4 && v != nullptr && !computed_in_init && st != fmi2OK)
            violation(call + " failed with valid arguments");
        if (st == fmi2OK && kind == 3 && n == 1 && s == nullptr) violation(call + " returned a NULL string");
    }

    void terminate() {
        const bool ok_expected = allowed("terminate");
        const int s = mutating("fmi2Terminate", "terminate", [&] { return f_.fmi2Terminate(c_); });
        if (ok_expected && s != fmi2OK) violation("fmi2Terminate failed in stepComplete");
        if (s == fmi2OK) phase_ = Phase::terminated;
    }

    void reset() {
        const int s = status("fmi2Reset", f_.fmi2Reset(c_));
        if (s != fmi2OK)
            violation("fmi2Reset failed");
        else {
            phase_ = Phase::instantiated;
            t_ = 0.0;
            small_map();
        }
    }

    void free_instance() {
        note("fmi2FreeInstance");
        ++calls;
        f_.fmi2FreeInstance(c_);
        c_ = nullptr;
        phase_ = Phase::none;
        states_.clear();  // freed with the instance
        blobs_.clear();
    }

    struct Saved {
        fmi2FMUstate state;
        Snapshot snap;
        Phase phase;
        double t;
    };
    struct Blob {
        std::vector<char> bytes;
        Snapshot snap;
        Phase phase;
        double t;
    };

    void fmu_state() {
        const int op = pick(9);
        if (op <= 1 || states_.empty()) {  // get, new or reusing one
            fmi2FMUstate s = nullptr;
            int reuse = -1;
            if (!states_.empty() && chance(0.3)) {
                reuse = pick(static_cast<int>(states_.size()));
                s = states_[reuse].state;
            }
            const bool null_arg = chance(0.03);
            const int st =
                status("fmi2GetFMUstate" + std::string(reuse >= 0 ? " (reuse)" : "") + (null_arg ? " NULL" : ""),
                       f_.fmi2GetFMUstate(c_, null_arg ? nullptr : &s));
            if (null_arg) {
                if (st != fmi2Error) violation("fmi2GetFMUstate(NULL) must be refused");
                return;
            }
            if (st != fmi2OK) {
                violation("fmi2GetFMUstate failed");
                return;
            }
            Saved saved{s, snapshot(c_), phase_, t_};
            if (reuse >= 0)
                states_[reuse] = saved;
            else
                states_.push_back(saved);
        } else if (op <= 3) {  // set one of ours
            const Saved& s = states_[pick(static_cast<int>(states_.size()))];
            const int st = status("fmi2SetFMUstate", f_.fmi2SetFMUstate(c_, s.state));
            if (st != fmi2OK) {
                violation("fmi2SetFMUstate of the instance's own state failed");
                return;
            }
            phase_ = s.phase;
            t_ = s.t;
            if (!(snapshot(c_) == s.snap)) violation("fmi2SetFMUstate did not restore every variable");
        } else if (op == 4) {  // set something that is not a state of this instance
            fmi2FMUstate bogus = nullptr;
            std::string what = "NULL";
            // a freed state's address, unless an allocation since has reused it for a live one
            if (!freed_states_.empty() && chance(0.5) &&
                std::none_of(states_.begin(), states_.end(),
                             [&](const Saved& x) { return x.state == freed_states_.back(); })) {
                bogus = freed_states_.back();
                what = "a freed state";
            } else if (other_ != nullptr && chance(0.5)) {
                fmi2FMUstate foreign = nullptr;
                if (f_.fmi2GetFMUstate(other_, &foreign) == fmi2OK) {
                    mutating("fmi2SetFMUstate(another instance's state)", "any",
                             [&] { return f_.fmi2SetFMUstate(c_, foreign); });
                    f_.fmi2FreeFMUstate(other_, &foreign);
                }
                return;
            } else if (chance(0.5)) {
                bogus = reinterpret_cast<fmi2FMUstate>(static_cast<std::uintptr_t>(0x1000));
                what = "a wild pointer";
            }
            const int st =
                mutating("fmi2SetFMUstate(" + what + ")", "any", [&] { return f_.fmi2SetFMUstate(c_, bogus); });
            if (st != fmi2Error) violation("fmi2SetFMUstate(" + what + ") must be refused");
        } else if (op == 5) {  // free one (sometimes twice)
            const int k = pick(static_cast<int>(states_.size()));
            fmi2FMUstate s = states_[k].state;
            const int st = status("fmi2FreeFMUstate", f_.fmi2FreeFMUstate(c_, &s));
            if (st != fmi2OK || s != nullptr) violation("fmi2FreeFMUstate failed or did not clear the pointer");
            freed_states_.push_back(states_[k].state);
            if (chance(0.3)) {
                fmi2FMUstate again = states_[k].state;
                if (status("fmi2FreeFMUstate (again)", f_.fmi2FreeFMUstate(c_, &again)) != fmi2Error)
                    violation("freeing an FMU state twice must be refused");
            }
            states_.erase(states_.begin() + k);
            fmi2FMUstate null_state = nullptr;
            if (status("fmi2FreeFMUstate(&NULL)", f_.fmi2FreeFMUstate(c_, &null_state)) != fmi2OK)
                violation("fmi2FreeFMUstate of a NULL state must succeed");
        } else if (op <= 7) {  // serialise
            const Saved& s = states_[pick(static_cast<int>(states_.size()))];
            std::size_t size = 0;
            if (status("fmi2SerializedFMUstateSize", f_.fmi2SerializedFMUstateSize(c_, s.state, &size)) != fmi2OK) {
                violation("fmi2SerializedFMUstateSize failed");
                return;
            }
            if (chance(0.1)) {
                if (status("fmi2SerializedFMUstateSize(size NULL)",
                           f_.fmi2SerializedFMUstateSize(c_, s.state, nullptr)) != fmi2Error)
                    violation("fmi2SerializedFMUstateSize(NULL) must be refused");
            }
            std::vector<char> bytes(size + 16);
            if (chance(0.1) && size > 0) {
                if (status("fmi2SerializeFMUstate(short buffer)",
                           f_.fmi2SerializeFMUstate(c_, s.state, bytes.data(), size - 1)) != fmi2Error)
                    violation("fmi2SerializeFMUstate into a short buffer must be refused");
            }
            if (status("fmi2SerializeFMUstate", f_.fmi2SerializeFMUstate(c_, s.state, bytes.data(), size)) != fmi2OK) {
                violation("fmi2SerializeFMUstate failed");
                return;
            }
            bytes.resize(size);
            blobs_.push_back(Blob{bytes, s.snap, s.phase, s.t});
        } else {  // deserialise: intact (then set) or corrupted
            std::vector<char> bytes;
            const Blob* blob = blobs_.empty() ? nullptr : &blobs_[pick(static_cast<int>(blobs_.size()))];
            std::string what = "intact";
            if (blob) bytes = blob->bytes;
            const int how = blob ? pick(6) : 3;
            if (how == 1 && !bytes.empty()) {
                bytes[pick(static_cast<int>(bytes.size()))] ^= static_cast<char>(1 + pick(255));
                what = "a flipped byte";
            } else if (how == 2 && !bytes.empty()) {
                bytes.resize(pick(static_cast<int>(bytes.size())));
                what = "truncated";
            } else if (how == 3) {
                bytes.resize(pick(300));
                for (auto& b : bytes) b = static_cast<char>(pick(256));
                what = "random bytes";
            } else if (how == 5 && bytes.size() > 8 && chance(0.5)) {
                // an edited state with a valid checksum (FNV-1a is no MAC): validated, not trusted
                bytes[pick(static_cast<int>(bytes.size() - 8))] ^= static_cast<char>(1 + pick(255));
                std::uint64_t h = 0xcbf29ce484222325ull;
                for (std::size_t i = 0; i + 8 < bytes.size(); ++i)
                    h = (h ^ static_cast<unsigned char>(bytes[i])) * 0x100000001b3ull;
                std::memcpy(bytes.data() + bytes.size() - 8, &h, 8);
                what = "edited, checksum recomputed";
            }
            fmi2FMUstate s = nullptr;
            const bool null_data = how == 4;
            if (null_data) what = "NULL data";
            const int st = status(
                "fmi2DeSerializeFMUstate(" + what + ")",
                f_.fmi2DeSerializeFMUstate(c_, null_data ? nullptr : bytes.data(), null_data ? 7 : bytes.size(), &s));
            if (what == "edited, checksum recomputed") {  // may be valid: refused or a state, never a crash
                if (st == fmi2OK)
                    f_.fmi2FreeFMUstate(c_, &s);
                else if (st != fmi2Error)
                    violation("fmi2DeSerializeFMUstate(" + what + ") returned " + std::to_string(st));
                return;
            }
            if (what != "intact" && st != fmi2Error) violation("fmi2DeSerializeFMUstate accepted " + what);
            if (st == fmi2OK) {
                if (s == nullptr) {
                    violation("fmi2DeSerializeFMUstate returned OK and no state");
                    return;
                }
                const int st2 = status("fmi2SetFMUstate(deserialised)", f_.fmi2SetFMUstate(c_, s));
                if (st2 != fmi2OK)
                    violation("fmi2SetFMUstate of a deserialised state failed");
                else {
                    phase_ = blob->phase;
                    t_ = blob->t;
                    if (!(snapshot(c_) == blob->snap)) violation("a deserialised state did not restore every variable");
                }
                states_.push_back(Saved{s, blob->snap, blob->phase, blob->t});
            }
        }
    }

    void status_queries() {
        const int kinds[] = {0, 1, 2, 3, 7, -1};
        const int kind = kinds[pick(6)];
        const bool null_value = chance(0.1);
        const int which = pick(5);
        fmi2Status sv = fmi2OK;
        fmi2Real rv = 0;
        fmi2Integer iv = 0;
        fmi2Boolean bv = 0;
        fmi2String strv = nullptr;
        const auto k = static_cast<fmi2StatusKind>(kind);
        int st = 0;
        switch (which) {
            case 0: st = f_.fmi2GetStatus(c_, k, null_value ? nullptr : &sv); break;
            case 1: st = f_.fmi2GetRealStatus(c_, k, null_value ? nullptr : &rv); break;
            case 2: st = f_.fmi2GetIntegerStatus(c_, k, null_value ? nullptr : &iv); break;
            case 3: st = f_.fmi2GetBooleanStatus(c_, k, null_value ? nullptr : &bv); break;
            default: st = f_.fmi2GetStringStatus(c_, k, null_value ? nullptr : &strv); break;
        }
        const std::string call = "fmi2Get*Status(" + std::to_string(which) + ", kind " + std::to_string(kind) +
                                 (null_value ? ", NULL" : "") + ")";
        status(call, st);
        if ((!allowed("status") || null_value || kind > 3 || kind < 0) && st != fmi2Error)
            violation(call + " must be refused");
        if (allowed("status") && !null_value && kind >= 0 && kind <= 3 && st != fmi2OK && st != fmi2Discard)
            violation(call + " must answer OK or Discard");
        if (which == 1 && kind == 2 && st == fmi2OK && rv != t_)
            violation("fmi2LastSuccessfulTime is not the time reached");
    }

    void debug_logging() {
        const char* good[] = {"logEvents", "logStatusError", "logAll"};
        const char* bad[] = {"logEvents", "noSuchCategory"};
        const int mode = pick(4);
        int st = 0;
        if (mode == 0)
            st = f_.fmi2SetDebugLogging(c_, fmi2True, 0, nullptr);
        else if (mode == 1)
            st = f_.fmi2SetDebugLogging(c_, fmi2True, 3, good);
        else if (mode == 2)
            st = f_.fmi2SetDebugLogging(c_, fmi2True, 2, bad);
        else
            st = f_.fmi2SetDebugLogging(c_, fmi2True, 2, nullptr);
        status("fmi2SetDebugLogging(mode " + std::to_string(mode) + ")", st);
        if ((mode <= 1) != (st == fmi2OK))
            violation("fmi2SetDebugLogging mode " + std::to_string(mode) + " answered " + status_name(st));
        if (chance(0.5)) f_.fmi2SetDebugLogging(c_, fmi2False, 0, nullptr);
    }

    void unsupported() {
        fmi2ValueReference vr = 0;
        fmi2Real r = 0;
        fmi2Integer order = 1;
        int st = 0;
        switch (pick(4)) {
            case 0: st = status("fmi2CancelStep", f_.fmi2CancelStep(c_)); break;
            case 1:
                st =
                    status("fmi2GetDirectionalDerivative", f_.fmi2GetDirectionalDerivative(c_, &vr, 1, &vr, 1, &r, &r));
                break;
            case 2:
                st = mutating("fmi2SetRealInputDerivatives", "any",
                              [&] { return f_.fmi2SetRealInputDerivatives(c_, &vr, 1, &order, &r); });
                break;
            default:
                st = status("fmi2GetRealOutputDerivatives", f_.fmi2GetRealOutputDerivatives(c_, &vr, 1, &order, &r));
                break;
        }
        if (st != fmi2Error) violation("an unsupported function did not return fmi2Error");
    }

    const Api& f_;
    const ModelInfo& m_;
    const Options& o_;
    std::mt19937_64 rng_;
    std::uint64_t seed_ = 0;
    std::deque<std::string> trace_;
    std::chrono::steady_clock::time_point last_ = std::chrono::steady_clock::now();
    std::string tmp_, good_map_, resource_uri_;
    std::vector<std::string> bad_maps_;
    std::vector<fmi2ValueReference> real_outputs_;
    long flux_map_vr_ = -1;
    fmi2Component c_ = nullptr, other_ = nullptr;
    Phase phase_ = Phase::none;
    double t_ = 0.0;
    fmi2CallbackFunctions cb_{}, cb_no_logger_{};  // alive as long as the instances
    std::vector<Saved> states_;
    std::vector<fmi2FMUstate> freed_states_;
    std::vector<Blob> blobs_;
};

// --- instances in threads: bit-identical to a sequential run ---
std::vector<double> drive(const Api& f, const ModelInfo& m, const std::string& uri, int instance, int steps) {
    fmi2CallbackFunctions cb{};
    cb.logger = logger;
    const std::string name = "thread" + std::to_string(instance);
    fmi2Component c =
        f.fmi2Instantiate(name.c_str(), fmi2CoSimulation, m.guid.c_str(), uri.c_str(), &cb, fmi2False, fmi2False);
    std::vector<double> out;
    if (c == nullptr) return out;
    std::vector<fmi2ValueReference> inputs, outputs;
    for (const auto& v : m.vars) {
        if (v.type != 'R') continue;
        if (v.causality == "input") inputs.push_back(v.vr);
        if (v.causality == "output") outputs.push_back(v.vr);
    }
    f.fmi2SetupExperiment(c, fmi2False, 0, 0, fmi2False, 0);
    f.fmi2EnterInitializationMode(c);
    if (f.fmi2ExitInitializationMode(c) > fmi2Warning) {
        f.fmi2FreeInstance(c);
        return out;
    }
    std::vector<double> start(inputs.size()), y(outputs.size());
    f.fmi2GetReal(c, inputs.data(), inputs.size(), start.data());
    for (int k = 0; k < steps; ++k) {
        std::vector<double> u(start);
        for (std::size_t i = 0; i < u.size(); ++i)
            u[i] = start[i] + 0.05 * (std::abs(start[i]) + 1) * std::sin(0.1 * k + i);
        f.fmi2SetReal(c, inputs.data(), inputs.size(), u.data());
        if (f.fmi2DoStep(c, k * 1e-4, 1e-4, fmi2True) > fmi2Warning) break;
        f.fmi2GetReal(c, outputs.data(), outputs.size(), y.data());
        out.insert(out.end(), y.begin(), y.end());
    }
    f.fmi2FreeInstance(c);
    return out;
}

int thread_check(const Api& f, const ModelInfo& m, const std::string& uri) {
    const int steps = 200, n = 4;
    const std::vector<double> sequential = drive(f, m, uri, 0, steps);
    std::vector<std::vector<double>> results(n);
    std::vector<std::thread> threads;
    for (int i = 0; i < n; ++i) threads.emplace_back([&, i] { results[i] = drive(f, m, uri, i + 1, steps); });
    for (auto& t : threads) t.join();
    int bad = 0;
    if (sequential.empty()) ++bad;
    for (int i = 0; i < n; ++i)
        if (results[i].size() != sequential.size() ||
            std::memcmp(results[i].data(), sequential.data(), sequential.size() * sizeof(double)) != 0)
            ++bad;
    std::printf("threads: %d instances in parallel threads, %d steps each, %zu outputs: %s\n", n, steps,
                sequential.size(), bad ? "DIFFERENT from the sequential run" : "bit-identical to the sequential run");
    return bad;
}

}  // namespace

int main(int argc, char** argv) {
    Options o;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        auto next = [&]() -> std::string {
            if (i + 1 >= argc) {
                std::fprintf(stderr, "%s needs a value\n", a.c_str());
                std::exit(2);
            }
            return argv[++i];
        };
        if (a == "--sequences")
            o.sequences = std::stol(next());
        else if (a == "--calls")
            o.calls = std::stoi(next());
        else if (a == "--seed")
            o.seed = std::stoull(next());
        else if (a == "--skip")
            o.skip.insert(next());
        else if (a == "--threads")
            o.threads = true;
        else if (a == "--verbose")
            verbose = true;
        else if (o.dir.empty() && a[0] != '-')
            o.dir = a;
        else {
            std::fprintf(stderr,
                         "usage: %s <unzipped fmu dir> [--sequences N] [--calls M] [--seed S] [--skip NAME]... "
                         "[--threads] [--verbose]\n",
                         argv[0]);
            return 2;
        }
    }
    if (o.dir.empty()) {
        std::fprintf(stderr, "usage: %s <unzipped fmu dir> [options]\n", argv[0]);
        return 2;
    }
    char resolved[PATH_MAX];
    if (realpath(o.dir.c_str(), resolved) == nullptr) {
        std::fprintf(stderr, "%s: no such directory\n", o.dir.c_str());
        return 2;
    }
    o.dir = resolved;
    const ModelInfo m = read_model_description(o.dir + "/modelDescription.xml");
    Api api;
    api.open_or_exit(fmu_binary::library_path(o.dir, m.id));
    if (std::strcmp(api.fmi2GetVersion(), "2.0") != 0 || std::strcmp(api.fmi2GetTypesPlatform(), "default") != 0) {
        std::printf("VIOLATION: version or types platform\n");
        return 1;
    }

    Fuzzer fuzz(api, m, o);
    for (long i = 0; i < o.sequences; ++i) fuzz.run_sequence(o.seed + static_cast<std::uint64_t>(i));
    int bad = static_cast<int>(fuzz.violations) + static_cast<int>(log_violations);
    if (log_violations) std::printf("VIOLATION: %ld malformed logger calls\n", log_violations.load());
    if (o.threads) bad += thread_check(api, m, resource_uri(o.dir));
    std::printf("%-30s %8s %8s %8s %8s %9s\n", "function", "OK", "Warning", "Discard", "Error", "seconds");
    for (const auto& [fn, st] : fuzz.per_function)
        std::printf("%-30s %8ld %8ld %8ld %8ld %9.3f\n", fn.c_str(), st[0], st[1], st[2], st[3], fuzz.seconds[fn]);
    std::printf("fuzz %s: %ld sequences (seeds %" PRIu64 "..%" PRIu64
                "), %ld calls: %ld OK, %ld Warning, %ld Discard, "
                "%ld Error; %ld log messages; %d violations\n",
                m.id.c_str(), o.sequences, o.seed, o.seed + o.sequences - 1, fuzz.calls, fuzz.statuses[0],
                fuzz.statuses[1], fuzz.statuses[2], fuzz.statuses[3], log_messages.load(), bad);
    return bad == 0 ? 0 : 1;
}
