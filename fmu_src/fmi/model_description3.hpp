// Writes the FMI 3.0 modelDescription.xml of a model from the same variable table, checks and
// start values as the FMI 2.0 one (model_description.hpp): the same names, value references,
// units, ranges, start values, causalities and variabilities. What FMI 3.0 changes:
// - the types are Float64, Int32, Boolean, String (a String's start is a <Start> element);
// - the independent variable `time` (FMI 3.0 asks for exactly one) has the value reference
//   kTimeValueReference (standard.hpp), beyond every table position;
// - <ModelStructure> names variables by value reference (<Output>, <InitialUnknown>), with the
//   same dependencies as the FMI 2.0 description;
// - <CoSimulation> has FMI 3.0's capability flags: no Event Mode, no early return, no
//   intermediate update.
// An FMU's FMI 3.0 generator is its FMI 3.0 .cpp compiled with IPMSM_FMI3_GENERATOR, where
// fmi3_entry_points.inc defines main() as model_description_main<MyModel, fmi3_standard>.
#pragma once

#include <cmath>
#include <cstddef>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "model_description.hpp"

namespace fmi {

inline const char* fmi3_type_name(Type t) {
    switch (t) {
        case Type::Real: return "Float64";
        case Type::Integer: return "Int32";
        case Type::Boolean: return "Boolean";
        case Type::String: return "String";
        case Type::UInt64: return "UInt64";
        case Type::RealArray: return "Float64";
    }
    return "?";
}

// The value reference of M's variable `name` (its table position).
template <class M>
std::size_t value_reference_of(const char* name) {
    const auto& vars = M::variables();
    for (std::size_t i = 0; i < vars.size(); ++i)
        if (std::string(vars[i].name) == name) return i;
    throw std::runtime_error(std::string("no variable ") + name);
}

template <class M>
std::string model_description3() {
    const M defaults = detail::checked_defaults<M>();
    const auto& vars = M::variables();
    std::ostringstream x;
    detail::write_root<M>(x, "3.0", "instantiationToken");
    x << "    canBeInstantiatedOnlyOncePerProcess=\"false\"\n"
      << "    canGetAndSetFMUState=\"true\"\n"
      << "    canSerializeFMUState=\"true\"\n"
      << "    providesDirectionalDerivatives=\"false\"\n"
      << "    providesAdjointDerivatives=\"false\"\n"
      << "    providesPerElementDependencies=\"false\"\n"
      << "    canHandleVariableCommunicationStepSize=\"true\"\n"
      << "    maxOutputDerivativeOrder=\"0\"\n"
      << "    providesIntermediateUpdate=\"false\"\n"
      << "    mightReturnEarlyFromDoStep=\"false\"\n"
      << "    canReturnEarlyAfterIntermediateUpdate=\"false\"\n"
      << "    hasEventMode=\"false\"\n"
      << "    providesEvaluateDiscreteStates=\"false\"/>\n";
    detail::write_units_categories_experiment<M>(x, "s", fmi3_standard);

    x << "  <ModelVariables>\n"
      << "    <Float64 name=\"time\" valueReference=\"" << kTimeValueReference
      << "\" description=\"Simulation time (the independent variable)\" causality=\"independent\""
         " variability=\"continuous\" unit=\"s\"/>\n";
    std::vector<std::size_t> outputs;  // value references
    for (std::size_t i = 0; i < vars.size(); ++i) {
        const auto& v = vars[i];
        const Type type = type_of(v);
        const bool computed = is_computed(v.causality);
        if (v.causality == Causality::output) outputs.push_back(i);
        x << "    <" << fmi3_type_name(type) << " name=\"" << xml_escape(v.name) << "\" valueReference=\"" << i
          << "\" description=\"" << xml_escape(v.description) << "\" causality=\"" << causality_name(v.causality)
          << "\" variability=\"" << variability_name(v.variability) << '"';
        if (computed) x << " initial=\"calculated\"";
        detail::write_type_attributes(x, v);
        if (computed)
            x << "/>\n";
        else if (type == Type::RealArray) {  // its lengths: <Dimension> elements naming structural parameters
            x << " start=\"" << detail::start_text(defaults, v) << "\">\n";
            for (const char* d : v.dimensions)
                x << "      <Dimension valueReference=\"" << value_reference_of<M>(d) << "\"/>\n";
            x << "    </Float64>\n";
        } else if (type == Type::String)
            x << ">\n      <Start value=\"" << detail::start_text(defaults, v) << "\"/>\n    </String>\n";
        else
            x << " start=\"" << detail::start_text(defaults, v) << "\"/>\n";
    }
    x << "  </ModelVariables>\n";

    // The same structure as the FMI 2.0 description (model_description.hpp says why), by value
    // reference: outputs depend on no input directly; in Initialization Mode on the parameters and
    // on every input or those the model declares.
    x << "  <ModelStructure>\n";
    for (std::size_t k : outputs) x << "    <Output valueReference=\"" << k << "\" dependencies=\"\"/>\n";
    for (std::size_t k : outputs) {
        x << "    <InitialUnknown valueReference=\"" << k << "\" dependencies=\"";
        const char* sep = "";
        for (std::size_t index : detail::initial_dependencies<M>(vars[k].name, fmi3_standard)) {
            x << sep << index - 1;
            sep = " ";
        }
        x << "\"/>\n";
    }
    x << "  </ModelStructure>\n</fmiModelDescription>\n";
    return x.str();
}

}  // namespace fmi
