// Writes the FMI 2.0 modelDescription.xml of a model (see model.hpp) from its variable table and
// static members; start values come from a default-constructed M(fmi::Context{}), so they have one
// source. The generator also checks the table against the standard's rules (names, descriptions,
// causality/variability combinations, types, units, ranges, finite start values) and fails with a
// list of the problems, which fails the build.
//
// An FMU's generator executable is its own .cpp compiled with IPMSM_FMI2_GENERATOR (add_fmu does
// that), where fmi2_entry_points.inc defines main() as model_description_main<MyModel>:
// `gen [out.xml] [--html table.html]`.
//
// `--html` also writes the variable reference (an HTML <section> with one table row per variable:
// name, value reference, causality, variability, type, unit, start, range, description), which
// add_fmu inserts into the FMU's documentation/index.html: the documentation cannot drift either.
#pragma once

#include <cmath>
#include <cstdio>
#include <exception>
#include <fstream>
#include <iostream>
#include <limits>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "fmi2_support.hpp"
#include "model.hpp"
#include "standard.hpp"
#include "variable.hpp"

namespace fmi {

// SI units known to the generator: exponents of the base units, and display units.
struct DisplayUnit {
    const char* name;
    double factor;  // display value = factor * value + offset
    double offset;
};
struct UnitInfo {
    const char* name;
    int kg, m, s, A, K, mol, cd, rad;
    std::vector<DisplayUnit> display;
};

inline const std::vector<UnitInfo>& unit_table() {
    static const double pi = std::acos(-1.0);
    static const std::vector<UnitInfo> table = {
        //  name     kg m  s   A  K mol cd rad
        {"1", 0, 0, 0, 0, 0, 0, 0, 0, {}},
        {"s", 0, 0, 1, 0, 0, 0, 0, 0, {{"ms", 1e3, 0}}},
        {"Hz", 0, 0, -1, 0, 0, 0, 0, 0, {}},
        {"m", 0, 1, 0, 0, 0, 0, 0, 0, {}},
        {"m/s", 0, 1, -1, 0, 0, 0, 0, 0, {{"km/h", 3.6, 0}}},
        {"kg", 1, 0, 0, 0, 0, 0, 0, 0, {}},
        {"kg.m2", 1, 2, 0, 0, 0, 0, 0, 0, {}},
        {"A", 0, 0, 0, 1, 0, 0, 0, 0, {}},
        {"V", 1, 2, -3, -1, 0, 0, 0, 0, {}},
        {"Ohm", 1, 2, -3, -2, 0, 0, 0, 0, {{"mOhm", 1e3, 0}}},
        {"H", 1, 2, -2, -2, 0, 0, 0, 0, {{"mH", 1e3, 0}}},
        {"Wb", 1, 2, -2, -1, 0, 0, 0, 0, {{"mWb", 1e3, 0}}},
        {"W", 1, 2, -3, 0, 0, 0, 0, 0, {{"kW", 1e-3, 0}}},
        {"J", 1, 2, -2, 0, 0, 0, 0, 0, {{"Wh", 1.0 / 3600.0, 0}, {"kWh", 1.0 / 3.6e6, 0}}},
        {"N", 1, 1, -2, 0, 0, 0, 0, 0, {}},
        {"N.m", 1, 2, -2, 0, 0, 0, 0, 0, {}},
        {"N.m.s", 1, 2, -1, 0, 0, 0, 0, 0, {}},  // angular impulse
        {"rad", 0, 0, 0, 0, 0, 0, 0, 1, {{"deg", 180.0 / pi, 0}}},
        {"rad/s", 0, 0, -1, 0, 0, 0, 0, 1, {{"rpm", 60.0 / (2.0 * pi), 0}}},
        {"K", 0, 0, 0, 0, 1, 0, 0, 0, {{"degC", 1.0, -273.15}}},
        {"1/K", 0, 0, 0, 0, -1, 0, 0, 0, {}},
        {"J/K", 1, 2, -2, 0, -1, 0, 0, 0, {}},  // heat capacity
        {"K/W", -1, -2, 3, 0, 1, 0, 0, 0, {}},  // thermal resistance
    };
    return table;
}

inline const UnitInfo* find_unit(const std::string& name) {
    for (const auto& u : unit_table())
        if (name == u.name) return &u;
    return nullptr;
}

inline std::string xml_escape(const std::string& s) {
    std::string out;
    for (char c : s) {
        switch (c) {
            case '&': out += "&amp;"; break;
            case '<': out += "&lt;"; break;
            case '>': out += "&gt;"; break;
            case '"': out += "&quot;"; break;
            case '\n': out += "&#10;"; break;
            case '\t': out += "&#9;"; break;
            case '\r': out += "&#13;"; break;
            default: out += c;
        }
    }
    return out;
}

namespace detail {

inline bool empty(const char* s) { return s == nullptr || s[0] == '\0'; }

// The rules of FMI 2.0 (section 2.2.7) this glue relies on; every problem found, one per line.
template <class M>
std::string table_problems(const M& defaults) {
    const auto& vars = M::variables();
    std::ostringstream p;
    std::set<std::string> names;
    if (!(M::default_step_size > 0.0) || !(M::default_stop_time > M::default_step_size))
        p << "default_step_size must be > 0 and default_stop_time > default_step_size\n";
    if (empty(M::model_identifier) || empty(M::guid) || empty(M::description))
        p << "model_identifier, guid and description must be non-empty\n";
    for (const auto& v : vars) {
        const std::string name = v.name != nullptr ? v.name : "";
        const std::string where = "variable \"" + name + "\": ";
        if (name.empty() || name.find_first_of("\r\n\t") != std::string::npos) p << where << "bad name\n";
        if (!names.insert(name).second) p << where << "the name is not unique\n";
        if (empty(v.description)) p << where << "needs a description\n";
        const Type actual = type_of(v);
        // An array has its elements' rules; a UInt64 an Integer's (FMI 3.0 only: fmi3_only).
        const Type type = actual == Type::RealArray ? Type::Real : actual == Type::UInt64 ? Type::Integer : actual;
        const Causality c = v.causality;
        const Variability var = v.variability;
        if ((c == Causality::parameter || c == Causality::structural_parameter) && var != Variability::fixed &&
            var != Variability::tunable)
            p << where << "a parameter must be fixed or tunable\n";
        if ((c == Causality::structural_parameter) != (actual == Type::UInt64))
            p << where << "a structural parameter is a UInt64, and a UInt64 is a structural parameter\n";
        else if (actual == Type::UInt64 && value_of<std::uint64_t>(defaults, v) == 0)
            p << where << "a structural parameter starts at 1 or more (FMI 3.0: no array is empty at its start)\n";
        if (actual == Type::RealArray) {
            if (c != Causality::parameter || v.dimensions.empty())
                p << where << "an array is a parameter with lengths\n";
            for (const char* d : v.dimensions) {
                const Variable<M>* length = find_variable<M>(d != nullptr ? d : "");
                if (length == nullptr || length->causality != Causality::structural_parameter)
                    p << where << "its length " << (d != nullptr ? d : "(null)") << " is not a structural parameter\n";
            }
            if (value_of<std::vector<double>>(defaults, v).size() != value_count(defaults, v))
                p << where << "the default-constructed model's array is not as long as its lengths say\n";
        } else if (!v.dimensions.empty())
            p << where << "only a Float64 array has lengths\n";
        if ((c == Causality::input || c == Causality::output) &&
            (var == Variability::fixed || var == Variability::tunable))
            p << where << "an input or output must be discrete or continuous\n";
        if (type != Type::Real && var == Variability::continuous)
            p << where << "only Reals can be continuous (use discrete)\n";
        const bool has_unit = !empty(v.unit), has_display = !empty(v.display_unit);
        if (type != Type::Real && (has_unit || has_display)) p << where << "only Reals have units in FMI 2.0\n";
        if (has_unit) {
            const UnitInfo* u = find_unit(v.unit);
            if (u == nullptr)
                p << where << "unit \"" << v.unit << "\" is not in model_description.hpp's unit_table()\n";
            else if (has_display) {
                bool found = false;
                for (const auto& d : u->display) found = found || std::string(d.name) == v.display_unit;
                if (!found)
                    p << where << "display unit \"" << v.display_unit << "\" is not defined for " << v.unit << "\n";
            }
        } else if (has_display)
            p << where << "a display unit needs a unit\n";
        const bool has_min = v.min != -std::numeric_limits<double>::infinity();
        const bool has_max = v.max != std::numeric_limits<double>::infinity();
        if ((type == Type::Boolean || type == Type::String) && (has_min || has_max || v.min_exclusive))
            p << where << "Booleans and Strings have no range\n";
        if (std::isnan(v.min) || std::isnan(v.max) || v.min > v.max) p << where << "min > max\n";
        if (type == Type::Integer) {
            for (double b : {v.min, v.max})
                if (std::isfinite(b) && (b != std::floor(b) || std::abs(b) > 2147483647.0))
                    p << where << "Integer bounds must be integers\n";
        }
        if (actual == Type::Real) {
            const double x = value_of<double>(defaults, v);
            if (!std::isfinite(x)) p << where << "the default-constructed model has " << number_text(x) << "\n";
        }
        if ((c == Causality::parameter || c == Causality::input || c == Causality::structural_parameter) &&
            (actual == Type::Real || actual == Type::Integer || actual == Type::UInt64)) {
            const double x = actual == Type::Real      ? value_of<double>(defaults, v)
                             : actual == Type::Integer ? value_of<int>(defaults, v)
                                                       : static_cast<double>(value_of<std::uint64_t>(defaults, v));
            if (!in_range(v, x))
                p << where << "start value " << number_text(x) << " is outside " << range_text(v) << "\n";
        }
    }
    return p.str();
}

// value_text, but a String bare and escaped (it goes into an attribute).
template <class M>
std::string start_text(const M& m, const Variable<M>& v) {
    if (type_of(v) == Type::String) return xml_escape(value_of<std::string>(m, v));
    return value_text(m, v);
}

// A model may declare, for some outputs, the only inputs its exit_initialization() computes them
// from: static std::vector<std::pair<std::string, std::vector<std::string>>> initial_inputs()
// ({output, {input, ...}}). An output it does not list depends on every input.
template <class M, class = void>
struct declares_initial_inputs : std::false_type {};
template <class M>
struct declares_initial_inputs<M, std::void_t<decltype(M::initial_inputs())>> : std::true_type {};

// The 1-based indices, ascending, of the parameters and of the inputs `output` depends on in
// Initialization Mode; throws for a declared name that is not an output or not an input.
template <class M>
std::vector<std::size_t> initial_dependencies(const std::string& output, const Standard& s) {
    const auto& vars = M::variables();
    auto index_of = [&](const std::string& name, Causality c) -> std::size_t {
        for (std::size_t i = 0; i < vars.size(); ++i)
            if (name == vars[i].name && vars[i].causality == c) return i + 1;
        throw std::runtime_error("initial_inputs(): \"" + name + "\" is not an " + causality_name(c));
    };
    std::vector<bool> inputs(vars.size(), true);  // default: every input
    if constexpr (declares_initial_inputs<M>::value) {
        for (const auto& [out, ins] : M::initial_inputs()) {
            index_of(out, Causality::output);
            if (out != output) continue;
            inputs.assign(vars.size(), false);
            for (const auto& in : ins) inputs[index_of(in, Causality::input) - 1] = true;
        }
    }
    std::vector<std::size_t> deps;
    for (std::size_t i = 0; i < vars.size(); ++i)
        if ((vars[i].causality == Causality::parameter || (vars[i].causality == Causality::input && inputs[i])) &&
            (s.time_variable || !fmi3_only(vars[i])))
            deps.push_back(i + 1);
    return deps;
}

// <UnitDefinitions> (the units the table uses, in table order, after `first` if given),
// <LogCategories> and <DefaultExperiment>: the same elements in FMI 2.0 and FMI 3.0.
template <class M>
void write_units_categories_experiment(std::ostringstream& x, const char* first, const Standard& s) {
    const auto& vars = M::variables();
    std::vector<const UnitInfo*> units;  // used ones, in table order
    if (first != nullptr) units.push_back(find_unit(first));
    for (const auto& v : vars)
        if (!empty(v.unit) && (s.time_variable || !fmi3_only(v))) {
            const UnitInfo* u = find_unit(v.unit);
            bool seen = false;
            for (const UnitInfo* w : units) seen = seen || w == u;
            if (!seen) units.push_back(u);
        }
    if (!units.empty()) {
        x << "  <UnitDefinitions>\n";
        for (const UnitInfo* u : units) {
            x << "    <Unit name=\"" << xml_escape(u->name) << "\">\n      <BaseUnit";
            const std::pair<const char*, int> exps[] = {{"kg", u->kg}, {"m", u->m},     {"s", u->s},   {"A", u->A},
                                                        {"K", u->K},   {"mol", u->mol}, {"cd", u->cd}, {"rad", u->rad}};
            for (const auto& [n, e] : exps)
                if (e != 0) x << ' ' << n << "=\"" << e << '"';
            x << "/>\n";
            for (const auto& d : u->display) {
                x << "      <DisplayUnit name=\"" << xml_escape(d.name) << "\" factor=\"" << number_text(d.factor)
                  << '"';
                if (d.offset != 0.0) x << " offset=\"" << number_text(d.offset) << '"';
                x << "/>\n";
            }
            x << "    </Unit>\n";
        }
        x << "  </UnitDefinitions>\n";
    }

    x << "  <LogCategories>\n";
    for (const auto& c : log_categories)
        x << "    <Category name=\"" << c.name << "\" description=\"" << xml_escape(c.description) << "\"/>\n";
    x << "  </LogCategories>\n";
    x << "  <DefaultExperiment startTime=\"0\" stopTime=\"" << number_text(M::default_stop_time) << "\" stepSize=\""
      << number_text(M::default_step_size) << "\"/>\n";
}

// The table's model with its start values, after the table's checks (std::runtime_error listing
// the problems).
template <class M>
M checked_defaults() {
    M defaults{Context{}};
    if (const std::string problems = table_problems(defaults); !problems.empty())
        throw std::runtime_error(std::string("the variable table of ") + M::model_identifier + " breaks FMI rules:\n" +
                                 problems);
    return defaults;
}

// The root element's opening tag, then <CoSimulation>'s first attributes: the same in FMI 2.0 and
// FMI 3.0 but for the version and the name of the GUID's attribute.
template <class M>
void write_root(std::ostringstream& x, const char* fmi_version, const char* token_attribute) {
    x << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
      << "<fmiModelDescription\n"
      << "  fmiVersion=\"" << fmi_version << "\"\n"
      << "  modelName=\"" << xml_escape(M::model_identifier) << "\"\n"
      << "  " << token_attribute << "=\"" << xml_escape(M::guid) << "\"\n"
      << "  description=\"" << xml_escape(M::description) << "\"\n"
#ifdef IPMSM_FMU_VERSION
      << "  version=\"" << xml_escape(IPMSM_FMU_VERSION) << "\"\n"
#endif
      << "  generationTool=\"ipmsm-fmu\"\n"
      << "  variableNamingConvention=\"flat\">\n"
      << "  <CoSimulation\n"
      << "    modelIdentifier=\"" << xml_escape(M::model_identifier) << "\"\n"
      << "    needsExecutionTool=\"false\"\n";
}

// A variable's unit, display unit, relativeQuantity and range: attributes of the type element in
// FMI 2.0 (<Real>), of the variable's own element in FMI 3.0 (<Float64>).
template <class M>
void write_type_attributes(std::ostringstream& x, const Variable<M>& v) {
    const Type type = type_of(v);
    if (!empty(v.unit)) x << " unit=\"" << xml_escape(v.unit) << '"';
    if (!empty(v.display_unit)) x << " displayUnit=\"" << xml_escape(v.display_unit) << '"';
    if (v.relative_quantity && type == Type::Real) x << " relativeQuantity=\"true\"";
    if (type == Type::Real || type == Type::Integer || type == Type::UInt64 || type == Type::RealArray) {
        auto bound = [&](double b) {  // xs:double, or xs:int (xs:unsignedLong)
            return (type == Type::Real || type == Type::RealArray) ? number_text(b)
                                                                   : std::to_string(static_cast<long long>(b));
        };
        if (std::isfinite(v.min)) x << " min=\"" << bound(v.min) << '"';
        if (std::isfinite(v.max)) x << " max=\"" << bound(v.max) << '"';
    }
}

}  // namespace detail

// The modelDescription.xml of M; throws std::runtime_error listing the table's problems.
template <class M>
std::string model_description() {
    const M defaults = detail::checked_defaults<M>();
    const auto& vars = M::variables();
    std::ostringstream x;
    detail::write_root<M>(x, "2.0", "guid");
    x << "    canHandleVariableCommunicationStepSize=\"true\"\n"
      << "    canInterpolateInputs=\"false\"\n"
      << "    maxOutputDerivativeOrder=\"0\"\n"
      << "    canRunAsynchronuously=\"false\"\n"
      << "    canBeInstantiatedOnlyOncePerProcess=\"false\"\n"
      << "    canNotUseMemoryManagementFunctions=\"true\"\n"
      << "    canGetAndSetFMUstate=\"true\"\n"
      << "    canSerializeFMUstate=\"true\"\n"
      << "    providesDirectionalDerivative=\"false\"/>\n";

    detail::write_units_categories_experiment<M>(x, nullptr, fmi2_standard);

    x << "  <ModelVariables>\n";
    std::vector<std::size_t> outputs;
    for (std::size_t i = 0; i < vars.size(); ++i) {
        const auto& v = vars[i];
        if (fmi3_only(v)) continue;  // FMI 2.0 has no such variable; its value reference stays unused
        const Type type = type_of(v);
        const bool computed = is_computed(v.causality);
        if (v.causality == Causality::output) outputs.push_back(i + 1);
        x << "    <ScalarVariable name=\"" << xml_escape(v.name) << "\" valueReference=\"" << i << "\" description=\""
          << xml_escape(v.description) << "\" causality=\"" << causality_name(v.causality) << "\" variability=\""
          << variability_name(v.variability) << '"';
        if (computed) x << " initial=\"calculated\"";
        x << ">\n      <" << type_name(type);
        detail::write_type_attributes(x, v);
        if (!computed) x << " start=\"" << detail::start_text(defaults, v) << '"';
        x << "/>\n    </ScalarVariable>\n";
    }
    x << "  </ModelVariables>\n";

    x << "  <ModelStructure>\n";
    if (!outputs.empty()) {
        // Outputs: none depends on an input directly. The glue computes them in
        // exit_initialization() and do_step() only, so an input set at a communication point
        // reaches an output after the next step, never at once (no algebraic loop for a master).
        x << "    <Outputs>\n";
        for (std::size_t k : outputs) x << "      <Unknown index=\"" << k << "\" dependencies=\"\"/>\n";
        // InitialUnknowns: an output read in Initialization Mode is what exit_initialization()
        // computes from the parameters and inputs: all of them, or the inputs the model declares.
        x << "    </Outputs>\n    <InitialUnknowns>\n";
        for (std::size_t k : outputs) {
            x << "      <Unknown index=\"" << k << "\" dependencies=\"";
            const char* sep = "";
            for (std::size_t i : detail::initial_dependencies<M>(vars[k - 1].name, fmi2_standard)) {
                x << sep << i;
                sep = " ";
            }
            x << "\"/>\n";
        }
        x << "    </InitialUnknowns>\n";
    }
    x << "  </ModelStructure>\n</fmiModelDescription>\n";
    return x.str();
}

// An array's lengths, " [n_i_d, n_i_q]"; "" for a scalar.
template <class M>
std::string array_dimensions_text(const Variable<M>& v) {
    std::string s;
    for (const char* d : v.dimensions) s += std::string(s.empty() ? " [" : ", ") + d;
    return s.empty() ? s : s + "]";
}

// The variable reference of M as an HTML section, from the same table as the XML (xml_escape's
// entities and character references are HTML too).
template <class M>
std::string variables_html(const Standard& s) {
    const M defaults{Context{}};
    const auto& vars = M::variables();
    std::ostringstream h;
    h << "<section id=\"variables\">\n<h2>Variable reference</h2>\n"
      << "<p>Generated from the FMU's variable table, the source of <code>modelDescription.xml</code>. "
      << "A value outside the range is refused with <code>" << s.error << "</code> and changes nothing; "
      << "<em>fixed</em> parameters can be set only before <code>" << s.exit_initialization_mode << "</code>. "
      << "Units are SI; the display unit is what a tool may show instead.</p>\n";
    if (s.major == 3)
        h << "<p>This is the FMU's FMI 3.0 build, from the same model and table as its FMI 2.0 build: where "
          << "this page names an FMI 2.0 function or type, read its FMI 3.0 counterpart (<code>fmi2SetReal</code>: "
          << "<code>fmi3SetFloat64</code>, <code>fmi2Error</code>: <code>fmi3Error</code>, Real: Float64, "
          << "Integer: Int32). FMI 3.0's independent variable <code>time</code> (s) has the value reference "
          << kTimeValueReference << ".</p>\n";
    h << "<table>\n"
      << "<tr><th>name</th><th>vr</th><th>causality</th><th>variability</th><th>type</th><th>unit</th>"
      << "<th>start</th><th>range</th><th>description</th></tr>\n";
    for (std::size_t i = 0; i < vars.size(); ++i) {
        const auto& v = vars[i];
        if (!s.time_variable && fmi3_only(v)) continue;
        const Type type = type_of(v);
        const bool computed = is_computed(v.causality);
        std::string unit = detail::empty(v.unit) ? "" : v.unit;
        if (!detail::empty(v.display_unit)) unit += std::string(" (") + v.display_unit + ")";
        std::string range;
        if (type == Type::Real || type == Type::Integer || type == Type::UInt64 || type == Type::RealArray) {
            range = range_text(v);
            if (range == "any finite value") range = (type == Type::Real || type == Type::RealArray) ? "finite" : "";
        }
        const std::string start = computed ? ""
                                           : (type == Type::String ? "\"" + detail::start_text(defaults, v) + "\""
                                                                   : detail::start_text(defaults, v));
        h << "<tr><td><code>" << xml_escape(v.name) << "</code></td><td>" << i << "</td><td>"
          << causality_name(v.causality) << "</td><td>" << variability_name(v.variability) << "</td><td>"
          << type_name(type) << array_dimensions_text(v) << "</td><td>" << xml_escape(unit) << "</td><td>" << start
          << "</td><td>" << xml_escape(range) << "</td><td>" << xml_escape(v.description) << "</td></tr>\n";
    }
    h << "</table>\n</section>\n";
    return h.str();
}

inline void write_file_atomically(const std::string& path, const std::string& text) {
    const std::string tmp = path + ".tmp";
    {
        std::ofstream f(tmp, std::ios::binary);
        f << text;
        if (!f.good()) throw std::runtime_error("cannot write " + tmp);
    }
    if (std::rename(tmp.c_str(), path.c_str()) != 0) throw std::runtime_error("cannot write " + path);
}

template <class M>
std::string model_description3();  // model_description3.hpp

// main() of a generator: `gen [out.xml] [--html table.html]`; the XML to stdout without out.xml;
// exit code 1 with the reason. S: the standard of the modelDescription.xml.
template <class M, const Standard& S = fmi2_standard>
int model_description_main(int argc, char** argv) {
    try {
        std::string xml_path, html_path;
        for (int i = 1; i < argc; ++i) {
            const std::string a = argv[i];
            if (a == "--html" && i + 1 < argc)
                html_path = argv[++i];
            else if (xml_path.empty() && a.rfind("--", 0) != 0)
                xml_path = a;
            else
                throw std::runtime_error("usage: " + std::string(argv[0]) + " [out.xml] [--html variables.html]");
        }
        std::string xml;
        if constexpr (S.major == 3)
            xml = model_description3<M>();
        else
            xml = model_description<M>();
        if (!html_path.empty()) write_file_atomically(html_path, variables_html<M>(S));
        if (xml_path.empty()) {
            std::cout << xml;
            return std::cout.good() ? 0 : 1;
        }
        write_file_atomically(xml_path, xml);
        return 0;
    } catch (const std::exception& e) {
        std::cerr << "modelDescription.xml of " << M::model_identifier << ": " << e.what() << '\n';
        return 1;
    }
}

}  // namespace fmi
