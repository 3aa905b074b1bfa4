// Variables forwarded to a part of the model (fmi/variable.hpp: fmi::Access, fmi::forward), and
// IpmsmDrive's parameters, declared once and forwarded to the controller and the plant.
#include <gtest/gtest.h>

#include <string>
#include <vector>

#include "drive/drive_model.hpp"
#include "source_tree.hpp"
#include "variable.hpp"

namespace {

struct Part {
    double gain = 2.0;
    std::string label = "a";
};

struct Whole {
    double own = 1.0;
    Part part;
    static const std::vector<fmi::Variable<Whole>>& variables() {
        static const std::vector<fmi::Variable<Whole>> table = {
            {"own", &Whole::own, fmi::Causality::parameter, fmi::Variability::fixed, "", "", "a member"},
            {"gain", fmi::forward(&Whole::part, &Part::gain), fmi::Causality::parameter, fmi::Variability::tunable, "",
             "", "forwarded"},
            {"label", fmi::forward(&Whole::part, &Part::label), fmi::Causality::parameter, fmi::Variability::fixed, "",
             "", "forwarded string"},
        };
        return table;
    }
};

TEST(VariableForwarding, ReadsAndWritesWhereTheValueLives) {
    Whole w;
    const auto* gain = fmi::find_variable<Whole>("gain");
    ASSERT_NE(gain, nullptr);
    EXPECT_EQ(fmi::type_of(*gain), fmi::Type::Real);
    EXPECT_EQ(fmi::value_of<double>(w, *gain), 2.0);
    fmi::set_value(w, *gain, 5.0);
    EXPECT_EQ(w.part.gain, 5.0);
    fmi::set_value(w, *fmi::find_variable<Whole>("label"), std::string("b"));
    EXPECT_EQ(w.part.label, "b");
    EXPECT_EQ(fmi::value_text(w, *fmi::find_variable<Whole>("label")), "\"b\"");
    Whole other;
    fmi::copy_value(w, other, *gain);
    EXPECT_EQ(other.part.gain, 5.0);
    EXPECT_EQ(fmi::parameter_number(w, "gain"), 5.0);
    EXPECT_EQ(fmi::parameter_number(w, "own"), 1.0);
    EXPECT_FALSE(fmi::parameter_number(w, "label"));  // a String
    EXPECT_EQ(fmi::find_variable<Whole>("none"), nullptr);
}

// pole_pairs is the controller's and the plant's: set once on the drive, both use it. Both
// warn that the default map's metadata says 4, the same text: it reaches the importer once.
TEST(VariableForwarding, DriveParameterReachesBothModels) {
    std::vector<std::string> warnings;
    fmi::Context context;
    context.resource_dir = ipmsm::source_path("fmu_src/resources");
    context.log_warning = [&](const std::string& m) { warnings.push_back(m); };
    ipmsm::DriveModel drive(context);
    const auto* pole_pairs = fmi::find_variable<ipmsm::DriveModel>("pole_pairs");
    ASSERT_NE(pole_pairs, nullptr);
    EXPECT_EQ(fmi::value_of<int>(drive, *pole_pairs), 4);
    fmi::set_value(drive, *pole_pairs, 3);
    EXPECT_EQ(fmi::value_of<int>(drive, *pole_pairs), 3);
    drive.u_dc = 355.0;
    drive.exit_initialization();
    int given = 0, prefixed = 0;
    for (const std::string& w : warnings) {
        if (w.find("but the parameter pole_pairs is 3") == std::string::npos) continue;
        ++given;
        prefixed += w.rfind("controller: ", 0) == 0 || w.rfind("plant: ", 0) == 0;
    }
    EXPECT_EQ(given, 1);
    EXPECT_EQ(prefixed, 1);
    // The inverter's parameters are forwarded to the plant's InverterParams.
    const auto* f_sw = fmi::find_variable<ipmsm::DriveModel>("f_sw");
    ASSERT_NE(f_sw, nullptr);
    EXPECT_EQ(fmi::value_of<double>(drive, *f_sw), ipmsm::InverterParams{}.f_sw);
}

}  // namespace
