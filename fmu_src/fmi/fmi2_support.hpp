// Small pieces shared by the FMI 2.0 glue and the model-description generator
// (model_description.hpp): instance states, log categories, resource-URI parsing, number text.
// Nothing here depends on a model or on the FMI C headers.
#pragma once

#include <array>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

namespace fmi {

// The co-simulation states of FMI 2.0 (section 4.2.4) that a synchronous FMU can be in.
// stepInProgress, stepFailed and stepCanceled never occur: fmi2DoStep computes synchronously.
enum class Phase : std::uint8_t {
    instantiated = 1,
    initialization_mode = 2,
    step_complete = 3,
    terminated = 4,
    error = 5,  // the glue could not restore a consistent model: only Get*, Reset, Free, FMU states
    fatal = 6,  // out of memory: only fmi2FreeInstance
};

inline const char* phase_name(Phase p) {
    switch (p) {
        case Phase::instantiated: return "instantiated";
        case Phase::initialization_mode: return "initializationMode";
        case Phase::step_complete: return "stepComplete";
        case Phase::terminated: return "terminated";
        case Phase::error: return "error";
        case Phase::fatal: return "fatal";
    }
    return "unknown";
}

// A set of phases, for "function F may be called in states S".
using PhaseMask = unsigned;
constexpr PhaseMask mask(Phase p) { return 1u << static_cast<unsigned>(p); }
template <class... P>
constexpr PhaseMask mask(Phase p, P... rest) { return mask(p) | mask(rest...); }

inline std::string mask_text(PhaseMask m) {
    std::string s;
    for (Phase p : {Phase::instantiated, Phase::initialization_mode, Phase::step_complete,
                    Phase::terminated, Phase::error, Phase::fatal})
        if (m & mask(p)) s += (s.empty() ? "" : ", ") + std::string(phase_name(p));
    return s.empty() ? "none" : s;
}

// Log categories, as listed in every modelDescription.xml. Index = bit in an instance's mask.
enum class LogCategory : unsigned { events, warning, discard, error, fatal, all };
struct LogCategoryInfo {
    const char* name;
    const char* description;
};
inline constexpr std::array<LogCategoryInfo, 6> log_categories{{
    {"logEvents", "Informative messages of the model (data loaded, settings used)"},
    {"logStatusWarning", "Warnings: the computation continues, the result may be questionable"},
    {"logStatusDiscard", "A call was discarded"},
    {"logStatusError", "Errors: the call was refused or failed and nothing was changed (always logged)"},
    {"logStatusFatal", "Fatal errors: the instance can only be freed (always logged)"},
    {"logAll", "Every category above, plus a trace of each FMI call"},
}};

// fmuResourceLocation (an URI) to a local directory path without a trailing '/'.
// Accepts file:///abs/path, file:/abs/path, file://localhost/abs/path (percent-encoded, e.g. %20
// for a space) and, leniently, a plain absolute path (taken as is). Anything else (NULL, another
// host, a relative path, a bad %-escape, an encoded NUL) gives "".
inline std::string resource_dir_from_uri(const char* uri) {
    if (uri == nullptr) return "";
    std::string s(uri);
    if (!s.empty() && s[0] == '/') {  // a plain path, not an URI
        while (s.size() > 1 && s.back() == '/') s.pop_back();
        return s;
    }
    auto starts = [&](const char* p) { return s.compare(0, std::char_traits<char>::length(p), p) == 0; };
    std::string path;
    if (starts("file:///")) path = s.substr(7);
    else if (starts("file://localhost/")) path = s.substr(16);
    else if (starts("file:/") && !starts("file://")) path = s.substr(5);
    else return "";
    std::string out;
    out.reserve(path.size());
    for (std::size_t i = 0; i < path.size(); ++i) {
        char c = path[i];
        if (c == '?' || c == '#') return "";  // a query or fragment has no meaning here
        if (c != '%') {
            out += c;
            continue;
        }
        if (i + 2 >= path.size()) return "";
        int v = 0;
        for (int k = 1; k <= 2; ++k) {
            const char h = path[i + k];
            v *= 16;
            if (h >= '0' && h <= '9') v += h - '0';
            else if (h >= 'a' && h <= 'f') v += h - 'a' + 10;
            else if (h >= 'A' && h <= 'F') v += h - 'A' + 10;
            else return "";
        }
        if (v == 0) return "";
        out += static_cast<char>(v);
        i += 2;
    }
    while (out.size() > 1 && out.back() == '/') out.pop_back();
    return out;
}

// The shortest text that reads back as the same double ("0.1", "1e-05", "inf", "nan").
inline std::string number_text(double v) {
    char buf[64];
    const auto r = std::to_chars(buf, buf + sizeof buf, v);
    return std::string(buf, r.ptr);
}

// 64-bit FNV-1a: a checksum of serialised states, and a per-model tag of instance pointers.
constexpr std::uint64_t fnv1a(const char* p, std::size_t n, std::uint64_t h = 0xcbf29ce484222325ull) {
    for (std::size_t i = 0; i < n; ++i) {
        h ^= static_cast<unsigned char>(p[i]);
        h *= 0x100000001b3ull;
    }
    return h;
}
constexpr std::uint64_t fnv1a(const char* s) {
    std::size_t n = 0;
    while (s[n] != '\0') ++n;
    return fnv1a(s, n);
}

}  // namespace fmi
