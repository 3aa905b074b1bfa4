// Unit tests of the pieces of the FMI glue that the ToyLag FMU cannot reach: the variable-table
// checks of the modelDescription.xml generator, its FMI 2.0 and FMI 3.0 output and its number
// formats (fmuResourceLocation parsing: tests/cpp/test_resource_uri.cpp, with both rule sets).
#include <gtest/gtest.h>

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "model_description3.hpp"

namespace {

using fmi::Causality;
using fmi::Variability;

// A model whose table breaks one rule per entry.
struct Bad {
    static constexpr const char* model_identifier = "Bad";
    static constexpr const char* guid = "{bad}";
    static constexpr const char* description = "A broken table";
    static constexpr double default_step_size = 0.1;
    static constexpr double default_stop_time = 1.0;
    static const std::vector<fmi::Variable<Bad>>& variables() {
        static const std::vector<fmi::Variable<Bad>> v = {
            {"a", &Bad::a, Causality::parameter, Variability::continuous, "V", "", "a"},
            {"a", &Bad::a, Causality::input, Variability::continuous, "furlong", "", "a again"},
            {"n", &Bad::n, Causality::output, Variability::continuous, "", "", "an Integer"},
            {"b", &Bad::b, Causality::output, Variability::continuous, "V", "rpm", ""},
            {"flag", &Bad::flag, Causality::input, Variability::discrete, "", "", "a Boolean", 0, 1},
            {"c", &Bad::c, Causality::parameter, Variability::fixed, "A", "", "c", 0, 1},
            {"n2", &Bad::n, Causality::parameter, Variability::fixed, "", "", "n2", 0.5, 10},
            {"s", &Bad::s, Causality::input, Variability::tunable, "", "", "s"},
            {"d", &Bad::a, Causality::parameter, Variability::fixed, "", "degC", "d"},
            {"i", &Bad::n, Causality::parameter, Variability::fixed, "A", "", "i"},
        };
        return v;
    }
    explicit Bad(const fmi::Context&) {}
    void exit_initialization() {}
    void do_step(double, double) {}
    template <class Field>
    void state_fields(Field&&) {}

    double a = 0.0, b = std::nan(""), c = 5.0;
    int n = 0;
    bool flag = false;
    std::string s;
};

struct Small {
    static constexpr const char* model_identifier = "Small";
    static constexpr const char* guid = "{small}";
    static constexpr const char* description = "Small & <fine>";
    static constexpr double default_step_size = 1e-4;
    static constexpr double default_stop_time = 0.1;
    static const std::vector<fmi::Variable<Small>>& variables() {
        static const std::vector<fmi::Variable<Small>> v = {
            {"u_dc", &Small::u_dc, Causality::input, Variability::continuous, "V", "", "DC link", 0, 2000, true},
            {"count", &Small::count, Causality::parameter, Variability::fixed, "", "", "count", 1, 1e7},
            {"name", &Small::name, Causality::parameter, Variability::fixed, "", "", "a \"name\""},
            {"T", &Small::T, Causality::output, Variability::continuous, "K", "degC", "T"},
            {"w", &Small::w, Causality::local, Variability::continuous, "rad/s", "rpm", "w"},
        };
        return v;
    }
    explicit Small(const fmi::Context&) {}
    void exit_initialization() {}
    void do_step(double, double) {}
    template <class Field>
    void state_fields(Field&&) {}

    double u_dc = 400.0;
    int count = 10000000;
    std::string name = "a<b>&\"c\"";
    double T = 300.0, w = 0.0;
};

TEST(ModelDescription, ReportsEveryBrokenRule) {
    const std::string p = fmi::detail::table_problems(Bad(fmi::Context{}));
    for (const char* expected : {
             "variable \"a\": a parameter must be fixed or tunable",
             "variable \"a\": the name is not unique",
             "unit \"furlong\" is not in model_description.hpp's unit_table()",
             "variable \"n\": only Reals can be continuous",
             "variable \"b\": needs a description",
             "display unit \"rpm\" is not defined for V",
             "variable \"b\": the default-constructed model has nan",
             "variable \"flag\": Booleans and Strings have no range",
             "variable \"c\": start value 5 is outside [0, 1]",
             "variable \"n2\": Integer bounds must be integers",
             "variable \"s\": an input or output must be discrete or continuous",
             "variable \"d\": a display unit needs a unit",
             "variable \"i\": only Reals have units",
         })
        EXPECT_NE(p.find(expected), std::string::npos) << "missing: " << expected << "\nin:\n" << p;
    EXPECT_THROW(fmi::model_description<Bad>(), std::runtime_error);
}

TEST(ModelDescription, WritesValidAttributes) {
    EXPECT_EQ(fmi::detail::table_problems(Small(fmi::Context{})), "");
    const std::string x = fmi::model_description<Small>();
    auto has = [&](const std::string& s) { return x.find(s) != std::string::npos; };
    EXPECT_TRUE(has("description=\"Small &amp; &lt;fine&gt;\""));
    EXPECT_TRUE(has("<Real unit=\"V\" min=\"0\" max=\"2000\" start=\"400\"/>"));
    EXPECT_TRUE(has("<Integer min=\"1\" max=\"10000000\" start=\"10000000\"/>"));  // xs:int, no 1e+07
    EXPECT_TRUE(has("<String start=\"a&lt;b&gt;&amp;&quot;c&quot;\"/>"));
    EXPECT_TRUE(
        has("causality=\"output\" variability=\"continuous\" initial=\"calculated\">\n      <Real unit=\"K\" "
            "displayUnit=\"degC\"/>"));
    EXPECT_TRUE(has("<DisplayUnit name=\"degC\" factor=\"1\" offset=\"-273.15\"/>"));
    EXPECT_TRUE(has("<DisplayUnit name=\"rpm\" factor=\"9.549296585513721\"/>"));
    EXPECT_TRUE(has("<DefaultExperiment startTime=\"0\" stopTime=\"0.1\" stepSize=\"1e-04\"/>"));
    // an output changes only in a step (no direct dependency); at initialisation it is computed
    // from the parameters and the input
    EXPECT_TRUE(has("<Outputs>\n      <Unknown index=\"4\" dependencies=\"\"/>\n    </Outputs>"));
    EXPECT_TRUE(has("<InitialUnknowns>\n      <Unknown index=\"4\" dependencies=\"1 2 3\"/>\n    </InitialUnknowns>"));
    EXPECT_FALSE(has("index=\"5\""));  // a local is not an output
}

// FMI 3.0: the same table, the same value references, units, ranges and starts; FMI 3.0's types,
// the independent variable time after the table, the structure by value reference.
TEST(ModelDescription, WritesFmi3) {
    const std::string x = fmi::model_description3<Small>();
    auto has = [&](const std::string& s) { return x.find(s) != std::string::npos; };
    EXPECT_TRUE(has("fmiVersion=\"3.0\""));
    EXPECT_TRUE(has("instantiationToken=\"{small}\""));
    EXPECT_FALSE(has("guid="));
    EXPECT_TRUE(has("hasEventMode=\"false\""));
    EXPECT_TRUE(has("canSerializeFMUState=\"true\""));
    EXPECT_TRUE(
        has("<Float64 name=\"time\" valueReference=\"2147483647\" description=\"Simulation time (the independent "
            "variable)\" causality=\"independent\" variability=\"continuous\" unit=\"s\"/>"));
    EXPECT_TRUE(has("<Unit name=\"s\">"));  // time's unit, though no variable of the table has it
    EXPECT_TRUE(
        has("<Float64 name=\"u_dc\" valueReference=\"0\" description=\"DC link\" causality=\"input\" "
            "variability=\"continuous\" unit=\"V\" min=\"0\" max=\"2000\" "
            "start=\"400\"/>"));
    EXPECT_TRUE(has("<Int32 name=\"count\" valueReference=\"1\""));
    EXPECT_TRUE(has("min=\"1\" max=\"10000000\" start=\"10000000\"/>"));
    EXPECT_TRUE(
        has("<String name=\"name\" valueReference=\"2\" description=\"a &quot;name&quot;\" "
            "causality=\"parameter\" variability=\"fixed\">\n      <Start value=\"a&lt;b&gt;&amp;&quot;c&quot;\"/>\n"
            "    </String>"));
    EXPECT_TRUE(
        has("<Float64 name=\"T\" valueReference=\"3\" description=\"T\" causality=\"output\" "
            "variability=\"continuous\" initial=\"calculated\" unit=\"K\" displayUnit=\"degC\"/>"));
    // FMI 2.0's index k is FMI 3.0's value reference k - 1
    EXPECT_TRUE(
        has("<ModelStructure>\n    <Output valueReference=\"3\" dependencies=\"\"/>\n"
            "    <InitialUnknown valueReference=\"3\" dependencies=\"0 1 2\"/>\n  </ModelStructure>"));
    EXPECT_FALSE(has("valueReference=\"4\" dependencies"));  // a local is not an output
    EXPECT_THROW(fmi::model_description3<Bad>(), std::runtime_error);
}

TEST(NumberText, ShortestRoundTrip) {
    EXPECT_EQ(fmi::number_text(0.1), "0.1");
    EXPECT_EQ(fmi::number_text(293.15), "293.15");
    EXPECT_EQ(fmi::number_text(-273.15), "-273.15");
    EXPECT_EQ(std::stod(fmi::number_text(60.0 / (2.0 * std::acos(-1.0)))), 60.0 / (2.0 * std::acos(-1.0)));
}

}  // namespace
