// The variable table: one source of truth for an FMU's variables. The FMI glue reads and writes
// model members through it, and the model-description generator writes the XML from it; the
// functions at the end describe a variable in words, for both.
#pragma once

#include <cmath>
#include <limits>
#include <string>
#include <type_traits>
#include <variant>
#include <vector>

#include "fmi2_support.hpp"

namespace fmi {

enum class Causality { parameter, input, output, local };
// Outputs and locals: the variables the model computes (a master cannot set them).
inline bool is_computed(Causality c) { return c == Causality::output || c == Causality::local; }
enum class Variability { fixed, tunable, discrete, continuous };

// A pointer to the model member that holds the variable's value; its type is the FMI type
// (double: Real, int: Integer, bool: Boolean, std::string: String).
template <class Model>
using Member = std::variant<double Model::*, int Model::*, bool Model::*, std::string Model::*>;

template <class Model>
struct Variable {
    const char* name;
    Member<Model> member;
    Causality causality;
    Variability variability;
    const char* unit;          // SI unit name ("" for none): "A", "V", "N.m", "rad/s", "K", "Ohm", ...
    const char* display_unit;  // "" for none; "rpm" for rad/s, "degC" for K
    const char* description;
    // Admissible range of a Real or Integer value; a set outside it is refused with fmi2Error.
    double min = -std::numeric_limits<double>::infinity();
    double max = std::numeric_limits<double>::infinity();
    bool min_exclusive = false;  // true: the value must be strictly greater than min (u_dc > 0)
};

// The FMI type of a variable: the index of its member pointer in Member<Model>.
enum class Type { Real = 0, Integer = 1, Boolean = 2, String = 3 };

template <class M>
Type type_of(const Variable<M>& v) {
    return static_cast<Type>(v.member.index());
}

inline const char* type_name(Type t) {
    switch (t) {
        case Type::Real: return "Real";
        case Type::Integer: return "Integer";
        case Type::Boolean: return "Boolean";
        case Type::String: return "String";
    }
    return "?";
}

inline const char* causality_name(Causality c) {
    switch (c) {
        case Causality::parameter: return "parameter";
        case Causality::input: return "input";
        case Causality::output: return "output";
        case Causality::local: return "local";
    }
    return "?";
}

inline const char* variability_name(Variability v) {
    switch (v) {
        case Variability::fixed: return "fixed";
        case Variability::tunable: return "tunable";
        case Variability::discrete: return "discrete";
        case Variability::continuous: return "continuous";
    }
    return "?";
}

template <class M>
bool in_range(const Variable<M>& v, double x) {
    return (v.min_exclusive ? x > v.min : x >= v.min) && x <= v.max;
}

// "[-100, 100]", "> 0", "> 0 and <= 5", "any finite value"
template <class M>
std::string range_text(const Variable<M>& v) {
    const bool has_min = std::isfinite(v.min), has_max = std::isfinite(v.max);
    if (v.min_exclusive || (has_min != has_max)) {
        std::string s;
        if (has_min) s = (v.min_exclusive ? "> " : ">= ") + number_text(v.min);
        if (has_max) s += (s.empty() ? "<= " : " and <= ") + number_text(v.max);
        return s.empty() ? "any finite value" : s;
    }
    if (!has_min) return "any finite value";
    return "[" + number_text(v.min) + ", " + number_text(v.max) + "]";
}

// The value of v in m as text: 0.1, 3, true, "a string".
template <class M>
std::string value_text(const M& m, const Variable<M>& v) {
    return std::visit(
        [&](auto p) -> std::string {
            using T = std::decay_t<decltype(m.*p)>;
            if constexpr (std::is_same_v<T, double>)
                return number_text(m.*p);
            else if constexpr (std::is_same_v<T, int>)
                return std::to_string(m.*p);
            else if constexpr (std::is_same_v<T, bool>)
                return m.*p ? "true" : "false";
            else
                return "\"" + m.*p + "\"";
        },
        v.member);
}

}  // namespace fmi
