// The flux map's metadata table (machine/flux_map_metadata.hpp) names parameters the FMUs have:
// each key's parameter is one of the controller's or the plant's, a Real or an Integer.
#include <gtest/gtest.h>

#include "controller/controller_model.hpp"
#include "machine/flux_map_metadata.hpp"
#include "plant_model.hpp"

namespace ipmsm {
namespace {

template <class M>
bool has_numeric_parameter(const char* name) {
    const auto* v = fmi::find_variable<M>(name);
    return v != nullptr && v->causality == fmi::Causality::parameter &&
           (fmi::type_of(*v) == fmi::Type::Real || fmi::type_of(*v) == fmi::Type::Integer);
}

TEST(MetadataParameters, EveryKeyNamesAParameterOfAModel) {
    for (const MetadataKey& k : metadata_keys())
        EXPECT_TRUE(has_numeric_parameter<ControllerModel>(k.parameter) ||
                    has_numeric_parameter<PlantModel>(k.parameter))
            << k.key << " -> " << k.parameter;
}

TEST(MetadataParameters, ModelsReportTheirParametersByName) {
    const fmi::Context context;
    const PlantModel plant(context);
    const ControllerModel controller(context);
    EXPECT_EQ(fmi::parameter_number(plant, "alpha_cu"), plant.motor.alpha_cu);
    EXPECT_EQ(fmi::parameter_number(controller, "pole_pairs"), controller.motor.pole_pairs);
    EXPECT_EQ(fmi::parameter_number(controller, "alpha_cu"), plant.motor.alpha_cu);  // both models' copper law
    EXPECT_EQ(fmi::parameter_number(controller, "fe_k_h"), plant.iron_loss.k_h);     // least loss: the plant's part
    EXPECT_FALSE(fmi::parameter_number(controller, "rtol"));                         // the plant's only
    EXPECT_FALSE(fmi::parameter_number(plant, "u_d"));                               // an input, not a parameter
}

}  // namespace
}  // namespace ipmsm
