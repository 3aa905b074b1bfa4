// The variable table: one source of truth for an FMU's variables. The FMI glue reads and writes
// model members through it, and the model-description generator writes the XML from it; the
// functions at the end describe a variable in words, for both.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <initializer_list>
#include <limits>
#include <optional>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include "fmi2_support.hpp"

namespace fmi {

// structural_parameter: FMI 3.0's, a length of array parameters, set in Configuration Mode only.
enum class Causality { parameter, input, output, local, structural_parameter };
// Outputs and locals: the variables the model computes (a master cannot set them).
inline bool is_computed(Causality c) { return c == Causality::output || c == Causality::local; }
enum class Variability { fixed, tunable, discrete, continuous };

// Where a variable's value lives, as its C++ type T (double: Real, int: Integer, bool: Boolean,
// std::string: String; FMI 3.0 only: std::uint64_t: UInt64, std::vector<double>: an array of
// Float64, its elements in row-major order): a member of the model (a pointer to it), or a part of the model that
// holds it, reached by a getter and a setter (a model made of other models forwards a variable
// to the one that owns it: IpmsmDrive's parameters are its controller's and plant's).
template <class Model, class T>
struct Access {
    T Model::*member = nullptr;
    std::function<T(const Model&)> get;         // forwarded (member == nullptr)
    std::function<void(Model&, const T&)> set;  // forwarded (member == nullptr)

    Access(T Model::*m) : member(m) {}  // NOLINT(google-explicit-constructor): tables list &M::x
    Access(std::function<T(const Model&)> g, std::function<void(Model&, const T&)> s)
        : get(std::move(g)), set(std::move(s)) {}

    T read(const Model& m) const { return member != nullptr ? m.*member : get(m); }
    void write(Model& m, const T& x) const {
        if (member != nullptr)
            m.*member = x;
        else
            set(m, x);
    }
};

// A variable's Access; the index of its alternative is the FMI type (Type, below).
template <class Model>
using Member = std::variant<Access<Model, double>, Access<Model, int>, Access<Model, bool>, Access<Model, std::string>,
                            Access<Model, std::uint64_t>, Access<Model, std::vector<double>>>;

// A variable forwarded to a member of a part of the model: part is the model's member that
// holds it (a sub-model, a parameter struct), field the part's member.
template <class Model, class Part, class T>
Access<Model, T> forward(Part Model::*part, T Part::*field) {
    return {[part, field](const Model& m) { return m.*part.*field; },
            [part, field](Model& m, const T& x) { m.*part.*field = x; }};
}

// ... or to a part's variable reached through the part's own Access.
template <class Model, class Part, class T>
Access<Model, T> forward(Part Model::*part, const Access<Part, T>& field) {
    return {[part, field](const Model& m) { return field.read(m.*part); },
            [part, field](Model& m, const T& x) { field.write(m.*part, x); }};
}

// An array's lengths (FMI 3.0): the names of the structural parameters that hold them, outermost
// first, at most two (a table's); none for a scalar.
struct Dimensions {
    const char* names[2] = {nullptr, nullptr};
    std::size_t size() const { return names[0] == nullptr ? 0 : (names[1] == nullptr ? 1 : 2); }
    bool empty() const { return size() == 0; }
    const char* const* begin() const { return names; }
    const char* const* end() const { return names + size(); }
};

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
    // A difference (FMI relativeQuantity): a tool shows it in the display unit without the unit's
    // offset (a margin of 25 K is 25 degC of difference, not -248 degC).
    bool relative_quantity = false;
    // An array (FMI 3.0): its lengths (its element count is their product); empty for a scalar.
    Dimensions dimensions = {};
};

// The FMI type of a variable: the index of its member pointer in Member<Model>. UInt64 and
// RealArray (an array of Float64) exist in FMI 3.0 only: an FMI 2.0 FMU has no such variable
// (fmi3_only, below), and its value references are the table's positions all the same.
enum class Type { Real = 0, Integer = 1, Boolean = 2, String = 3, UInt64 = 4, RealArray = 5 };

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
        case Type::UInt64: return "UInt64";
        case Type::RealArray: return "Float64 array";
    }
    return "?";
}

// A variable that FMI 2.0 cannot express: an FMI 2.0 FMU leaves it out (its description, its
// value references, its FMU states), an FMI 3.0 FMU has it.
template <class M>
bool fmi3_only(const Variable<M>& v) {
    const Type t = type_of(v);
    return t == Type::UInt64 || t == Type::RealArray || v.causality == Causality::structural_parameter;
}

inline const char* causality_name(Causality c) {
    switch (c) {
        case Causality::parameter: return "parameter";
        case Causality::input: return "input";
        case Causality::output: return "output";
        case Causality::local: return "local";
        case Causality::structural_parameter: return "structuralParameter";
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

// Why x is not a value of v ("R_s = -1 Ohm is out of range: it must be > 0"), or "" if it is one:
// the one check of a Real or Integer value, for fmi2SetReal/Integer and for an FMU state's fields.
template <class M>
std::string range_error(const Variable<M>& v, double x) {
    if (!std::isfinite(x)) return std::string(v.name) + " = " + number_text(x) + " is not a finite number";
    if (in_range(v, x)) return "";
    const std::string unit = (v.unit != nullptr && v.unit[0] != '\0') ? std::string(" ") + v.unit : "";
    return std::string(v.name) + " = " + number_text(x) + unit + " is out of range: it must be " + range_text(v);
}

// An array's values as text, space-separated (FMI 3.0's start attribute): "0.1 0.2"; "" if empty.
inline std::string array_text(const std::vector<double>& x) {
    std::string s;
    for (double e : x) s += (s.empty() ? "" : " ") + number_text(e);
    return s;
}

// The value of v in m as text: 0.1, 3, true, "a string", "0.1 0.2" (an array).
template <class M>
std::string value_text(const M& m, const Variable<M>& v) {
    return std::visit(
        [&](const auto& a) -> std::string {
            const auto x = a.read(m);
            using T = std::decay_t<decltype(x)>;
            if constexpr (std::is_same_v<T, double>)
                return number_text(x);
            else if constexpr (std::is_same_v<T, int>)
                return std::to_string(x);
            else if constexpr (std::is_same_v<T, bool>)
                return x ? "true" : "false";
            else if constexpr (std::is_same_v<T, std::uint64_t>)
                return std::to_string(x);
            else if constexpr (std::is_same_v<T, std::vector<double>>)
                return array_text(x);
            else
                return "\"" + x + "\"";
        },
        v.member);
}

// The value of v in m as type T (the variable's C++ type: std::bad_variant_access otherwise).
template <class T, class M>
T value_of(const M& m, const Variable<M>& v) {
    return std::get<Access<M, T>>(v.member).read(m);
}

// Sets v in m to x, of type T (the variable's C++ type).
template <class T, class M>
void set_value(M& m, const Variable<M>& v, const T& x) {
    std::get<Access<M, T>>(v.member).write(m, x);
}

// M's variable called `name`, or nullptr: the one lookup by name in a model's table.
template <class M>
const Variable<M>* find_variable(const std::string& name) {
    for (const auto& v : M::variables())
        if (name == v.name) return &v;
    return nullptr;
}

// The number of values of v in m: 1 for a scalar, an array's element count (the product of its
// lengths, the structural parameters it names; saturated, though their ranges bound it).
template <class M>
std::size_t value_count(const M& m, const Variable<M>& v) {
    std::size_t n = 1;
    for (const char* d : v.dimensions) {
        const Variable<M>* length = find_variable<M>(d);
        const std::uint64_t x = length != nullptr ? value_of<std::uint64_t>(m, *length) : 0;
        n = (x != 0 && n > std::numeric_limits<std::size_t>::max() / x) ? std::numeric_limits<std::size_t>::max()
                                                                        : n * static_cast<std::size_t>(x);
    }
    return n;
}

// "psi_d: n_i_d x n_i_q = 4 x 5 = 20 values" (an array's count, explained)
template <class M>
std::string count_text(const M& m, const Variable<M>& v) {
    std::string names, values;
    for (const char* d : v.dimensions) {
        const Variable<M>* length = find_variable<M>(d);
        names += std::string(names.empty() ? "" : " x ") + d;
        values += std::string(values.empty() ? "" : " x ") +
                  (length != nullptr ? std::to_string(value_of<std::uint64_t>(m, *length)) : "?");
    }
    return std::string(v.name) + ": " + names + " = " + values + " = " + std::to_string(value_count(m, v)) + " values";
}

// An array whose size is not its lengths' product (they changed) becomes zeros of the new size:
// after a structural parameter is set, its arrays are to be set again.
template <class M>
void resize_arrays(M& m) {
    for (const auto& v : M::variables())
        if (type_of(v) == Type::RealArray) {
            const std::size_t n = value_count(m, v);
            if (value_of<std::vector<double>>(m, v).size() != n) set_value(m, v, std::vector<double>(n, 0.0));
        }
}

// The value of m's Real or Integer parameter `name` as a double; nullopt if m has none.
template <class M>
std::optional<double> parameter_number(const M& m, const std::string& name) {
    const Variable<M>* v = find_variable<M>(name);
    if (v == nullptr || v->causality != Causality::parameter) return std::nullopt;
    if (type_of(*v) == Type::Real) return value_of<double>(m, *v);
    if (type_of(*v) == Type::Integer) return value_of<int>(m, *v);
    return std::nullopt;
}

// --- Parts: parameter structs a model holds (the motor, its iron loss, the inverter), each with
// its variables declared once, in a table of its own: `variables_of(const Part*)`, found by
// argument-dependent lookup in the part's namespace. A model places them in its table by name
// (part_variable), where their value references are to be; a model made of models (IpmsmDrive)
// forwards them by name (its table is generated from the models').

template <class Part>
const std::vector<Variable<Part>>& part_table() {
    return variables_of(static_cast<const Part*>(nullptr));
}

// A variable of a part (a parameter struct, a sub-model) as a variable of the model that holds
// the part as its member `part`: the part's declaration (unit, range, description), the value
// forwarded to the part.
template <class Model, class Part>
Variable<Model> forward_variable(Part Model::*part, const Variable<Part>& v) {
    Member<Model> member = std::visit([&](const auto& a) -> Member<Model> { return forward(part, a); }, v.member);
    return {v.name, std::move(member), v.causality,         v.variability, v.unit, v.display_unit, v.description, v.min,
            v.max,  v.min_exclusive,   v.relative_quantity, v.dimensions};
}

// The part's variable `name` as a variable of the model that holds the part (forward_variable).
template <class Model, class Part>
Variable<Model> part_variable(Part Model::*part, const char* name) {
    for (const auto& v : part_table<Part>())
        if (std::string(v.name) == name) return forward_variable(part, v);
    throw std::logic_error(std::string("no part variable ") + name);
}

// Every variable of the part, in the part's order: for a model that places the whole part at once.
template <class Model, class Part>
std::vector<Variable<Model>> part_variables(Part Model::*part) {
    std::vector<Variable<Model>> out;
    for (const auto& v : part_table<Part>()) out.push_back(part_variable(part, v.name));
    return out;
}

// The part's variables the table does not have yet, appended: a model's table ends with this for
// each part it holds, so that a parameter added to a part reaches every holder by itself, at a new
// value reference. (A model's own new variables go before these lines while they append nothing;
// after a release has recorded what they appended, those are placed by name first:
// tests/python/test_value_references.py fails while a released value reference moves.)
template <class Model, class Part>
void append_rest(std::vector<Variable<Model>>& table, Part Model::*part) {
    for (const auto& v : part_table<Part>()) {
        bool has = false;
        for (const auto& t : table) has = has || std::string(t.name) == v.name;
        if (!has) table.push_back(forward_variable(part, v));
    }
}

// The variables of a model's table: entries and whole parts, in order (value reference = index).
template <class Model>
std::vector<Variable<Model>> join(std::initializer_list<std::vector<Variable<Model>>> pieces) {
    std::vector<Variable<Model>> out;
    for (const auto& p : pieces) out.insert(out.end(), p.begin(), p.end());
    return out;
}

// Copies the value of v from one model to another.
template <class M>
void copy_value(const M& from, M& to, const Variable<M>& v) {
    std::visit([&](const auto& a) { a.write(to, a.read(from)); }, v.member);
}

}  // namespace fmi
