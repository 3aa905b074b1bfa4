// Small pieces shared by the FMI 2.0 glue and the model-description generator
// (model_description.hpp): instance states, log categories, number text (the resource URI: resource_uri.hpp).
// Nothing here depends on a model or on the FMI C headers.
#pragma once

#include <array>
#include <charconv>
#include <cmath>
#include <cstddef>
#include <cstdint>
#include <string>

#include "resource_uri.hpp"

namespace fmi {

// The co-simulation states of FMI 2.0 (section 4.2.4) that a synchronous FMU can be in.
// stepInProgress, stepFailed and stepCanceled never occur: fmi2DoStep computes synchronously.
enum class Phase : std::uint8_t {
    instantiated = 1,
    initialization_mode = 2,
    step_complete = 3,
    terminated = 4,
    error = 5,               // the glue could not restore a consistent model: only Get*, Reset, Free, FMU states
    fatal = 6,               // out of memory: only fmi2FreeInstance
    configuration_mode = 7,  // FMI 3.0: structural parameters may be set (from Instantiated, back to it)
};

// A state's name in messages, as the standard `major` (2, 3) names it; error and fatal are the glue's.
inline const char* phase_name(Phase p, int major = 2) {
    if (major == 3) {
        switch (p) {
            case Phase::instantiated: return "Instantiated";
            case Phase::initialization_mode: return "InitializationMode";
            case Phase::step_complete: return "StepMode";
            case Phase::terminated: return "Terminated";
            case Phase::configuration_mode: return "ConfigurationMode";
            default: break;
        }
    }
    switch (p) {
        case Phase::instantiated: return "instantiated";
        case Phase::initialization_mode: return "initializationMode";
        case Phase::step_complete: return "stepComplete";
        case Phase::terminated: return "terminated";
        case Phase::error: return "error";
        case Phase::fatal: return "fatal";
        case Phase::configuration_mode: return "configurationMode";
    }
    return "unknown";
}

// A set of phases, for "function F may be called in states S".
using PhaseMask = unsigned;
constexpr PhaseMask mask(Phase p) { return 1u << static_cast<unsigned>(p); }
template <class... P>
constexpr PhaseMask mask(Phase p, P... rest) {
    return mask(p) | mask(rest...);
}

inline std::string mask_text(PhaseMask m, int major = 2) {
    std::string s;
    for (Phase p : {Phase::instantiated, Phase::configuration_mode, Phase::initialization_mode, Phase::step_complete,
                    Phase::terminated, Phase::error, Phase::fatal})
        if (m & mask(p)) s += (s.empty() ? "" : ", ") + std::string(phase_name(p, major));
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
