// The variable table: one source of truth for an FMU's variables. The FMI glue reads and writes
// model members through it, and the model-description generator writes the XML from it.
#pragma once

#include <limits>
#include <string>
#include <variant>
#include <vector>

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

}  // namespace fmi
