// The controller's temperatures (docs/thermal.md, "Controller"): the winding's copper law written
// once for the plant and the controller; the thermal derating's factor; the controller's R_s and
// derating from its inputs; IpmsmDrive's derating parameters reaching the controller.
#include <gtest/gtest.h>

#include <cmath>
#include <string>
#include <string_view>

#include "control/derating.hpp"
#include "controller/controller_model.hpp"
#include "drive/drive_model.hpp"
#include "machine/winding_resistance.hpp"
#include "plant_model.hpp"
#include "source_tree.hpp"
#include "variable.hpp"

namespace {

using ipmsm::DeratingLimits;
using ipmsm::thermal_derating;

TEST(Derating, LinearBetweenStartAndMaximumExactOneBelow) {
    const DeratingLimits d{453.15, 423.15, 25.0};
    EXPECT_EQ(thermal_derating(d, 293.15, 293.15), 1.0);
    EXPECT_EQ(thermal_derating(d, 428.15, 398.15), 1.0);  // both at their start: still exactly 1
    EXPECT_NEAR(thermal_derating(d, 443.15, 293.15), 0.4, 1e-12);
    EXPECT_NEAR(thermal_derating(d, 293.15, 413.15), 0.4, 1e-12);
    EXPECT_NEAR(thermal_derating(d, 440.65, 418.15), 0.2, 1e-12);  // the smaller factor: the magnets'
    EXPECT_EQ(thermal_derating(d, 453.15, 293.15), 0.0);
    EXPECT_EQ(thermal_derating(d, 500.0, 293.15), 0.0);
    EXPECT_EQ(thermal_derating(d, 293.15, 430.0), 0.0);
}

TEST(Derating, WindingResistanceIsThePlantsLaw) {
    EXPECT_EQ(ipmsm::winding_resistance(0.012, 0.00393, 293.15, 293.15), 0.012);
    EXPECT_NEAR(ipmsm::winding_resistance(0.012, 0.00393, 393.15, 293.15), 0.012 * 1.393, 1e-15);
    EXPECT_TRUE(ipmsm::winding_law_error(0.00393, 293.15).empty());
    EXPECT_NE(ipmsm::winding_law_error(0.009, 573.15).find("negative"), std::string::npos);
    EXPECT_EQ(ipmsm::PlantModel{fmi::Context{}}.motor.alpha_cu, ipmsm::ControllerModel{fmi::Context{}}.motor.alpha_cu);
}

fmi::Context resources() {
    fmi::Context context;
    context.resource_dir = ipmsm::source_path("fmu_src/resources");
    return context;
}

TEST(Derating, ControllerLimitsTheTorqueAtAHotWinding) {
    ipmsm::ControllerModel free(resources()), hot(resources());
    for (ipmsm::ControllerModel* m : {&free, &hot}) {
        m->T_ref = 400.0;
        m->w_m = 100.0;
        m->u_dc = 355.0;
        m->T_winding = 443.15;  // 10 K below T_winding_max: factor 0.4
    }
    free.T_winding_max = 573.15;
    free.exit_initialization();
    hot.exit_initialization();
    free.do_step(0.0, 1e-4);
    hot.do_step(0.0, 1e-4);
    EXPECT_EQ(free.derating, 1.0);
    EXPECT_NEAR(hot.derating, 0.4, 1e-12);
    EXPECT_NEAR(hot.T_max, 0.4 * free.T_max, 1e-9 * free.T_max);
    EXPECT_EQ(hot.T_cmd, hot.T_max);
    EXPECT_LT(std::hypot(hot.i_d_ref, hot.i_q_ref), std::hypot(free.i_d_ref, free.i_q_ref));
}

TEST(Derating, DriveHasTheTemperatureParametersOnce) {
    ipmsm::DriveModel drive(resources());
    int found = 0;
    for (const auto& v : ipmsm::DriveModel::variables())
        for (const char* name : {"alpha_cu", "T_winding_ref", "T_winding_max", "T_magnet_max", "derating_margin",
                                 "T_magnet_estimate_error", "derating", "T_winding"})
            found += std::string_view(v.name) == name;  // names by content: literals are not pooled everywhere
    EXPECT_EQ(found, 8);
    fmi::set_value(drive, *fmi::find_variable<ipmsm::DriveModel>("T_winding_max"), 400.0);
    EXPECT_EQ(fmi::parameter_number(drive, "T_winding_max"), 400.0);
    EXPECT_EQ(fmi::parameter_number(drive, "derating_margin"), 25.0);
    EXPECT_EQ(fmi::parameter_number(drive, "T_magnet_estimate_error"), 0.0);
}

}  // namespace
