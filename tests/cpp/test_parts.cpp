// The parameter structs ("parts": parts/part_variables.hpp) each declared once: every model that
// holds a part has all its variables, with the part's declaration; IpmsmDrive forwards every
// parameter of its models.
#include <gtest/gtest.h>

#include <string>

#include "controller/controller_model.hpp"
#include "drive/drive_model.hpp"
#include "parts/part_variables.hpp"
#include "plant_model.hpp"

namespace ipmsm {
namespace {

template <class Model, class Part>
void expect_holds(const char* model, const char* part) {
    for (const auto& p : fmi::part_table<Part>()) {
        const auto* v = fmi::find_variable<Model>(p.name);
        ASSERT_NE(v, nullptr) << model << " holds the " << part << " but lacks its " << p.name
                              << ": place fmi::part_variable at the end of its table";
        EXPECT_EQ(std::string(v->unit), p.unit) << model << "." << p.name;
        EXPECT_EQ(std::string(v->description), p.description) << model << "." << p.name;
        EXPECT_EQ(v->min, p.min) << model << "." << p.name;
        EXPECT_EQ(v->max, p.max) << model << "." << p.name;
    }
}

TEST(Parts, EveryHolderHasEveryVariableOfItsParts) {
    expect_holds<ControllerModel, MotorParams>("IpmsmController", "motor");
    expect_holds<PlantModel, MotorParams>("IpmsmPlant", "motor");
    expect_holds<PlantModel, IronLossModel>("IpmsmPlant", "iron loss");
    expect_holds<PlantModel, InverterParams>("IpmsmPlant", "inverter");
    expect_holds<PlantModel, thermal::LptnParams>("IpmsmPlant", "thermal network");
}

template <class Model>
void expect_forwarded(const char* model) {
    for (const auto& v : Model::variables()) {
        if (v.causality == fmi::Causality::parameter) {
            EXPECT_NE(fmi::find_variable<DriveModel>(v.name), nullptr) << "IpmsmDrive lacks " << model << "." << v.name;
        }
    }
}

TEST(Parts, TheDriveForwardsEveryParameterOfItsModels) {
    expect_forwarded<ControllerModel>("IpmsmController");
    expect_forwarded<PlantModel>("IpmsmPlant");
}

}  // namespace
}  // namespace ipmsm
