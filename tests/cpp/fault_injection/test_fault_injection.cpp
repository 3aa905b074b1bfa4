// The command check catches a corrupted command: built only into fault_injection_tests, whose
// control library is compiled with IPMSM_FAULT_INJECTION (tests/CMakeLists.txt); the FMUs' is not.
#include <gtest/gtest.h>

#include <cmath>
#include <memory>

#include "control/fault_injection.hpp"
#include "control/saturated_optimal_current.hpp"
#include "flux_map_generators.hpp"
#include "machine/magnet_flux.hpp"

using namespace ipmsm;

TEST(FaultInjection, TheCheckCatchesACorruptedCommand) {
    // The default motor's nominal inductances on a saturating map (a q axis levelling off).
    const auto map =
        std::make_shared<const FluxMap>(saturating_flux_map(2.0e-4, 6.0e-4, 0.078, 150.0, 0.1, 500.0, 650.0, 53));
    const MagnetFlux flux(*map, 0.0);
    SaturatedOptimalCurrent solver(map, 4);
    const OperatingLimits lim{4 * 300.0, 0.95 * 355.0 / std::sqrt(3.0), 500.0};
    const CurrentCommand good = solver.solve(150.0, lim, 0.012, 0.0, Recursion::optimal);
    ASSERT_EQ(solver.last_check.finding, CheckFinding::passed);

    fault_injection::current_scale() = 1.2;  // 20 % more current: 20 to 40 % more torque
    const CurrentCommand c = solver.solve(150.0, lim, 0.012, 0.0, Recursion::optimal);
    fault_injection::current_scale() = 1.0;
    EXPECT_EQ(solver.last_check.finding, CheckFinding::torque);
    EXPECT_TRUE(solver.last_check.replaced);
    EXPECT_NEAR(solver.last_check.rejected.i_d, 1.2 * good.i_d, 1e-9 * 500.0);
    EXPECT_GT(std::abs(solver.last_check.T_made), 150.0 * 1.1);
    // The robust search's command: the torque, with the least current (the good one's).
    EXPECT_NEAR(6.0 * flux.reduced_torque(c.i_d, c.i_q), 150.0, 1e-6 * c.torque_max);
    EXPECT_NEAR(std::hypot(c.i_d, c.i_q), std::hypot(good.i_d, good.i_q), 1e-6 * 500.0);

    fault_injection::current_scale() = 0.999;  // 0.1 % less current: less torque, caught as well
    solver.solve(150.0, lim, 0.012, 0.0, Recursion::optimal);
    fault_injection::current_scale() = 1.0;
    EXPECT_EQ(solver.last_check.finding, CheckFinding::torque);
}

// T_max's check (docs/controller.md, "T_max checked"): a T_max whose point is off the limits is not
// a local maximum; the robust search finds the map's T_max and the command is made from it.
TEST(FaultInjection, TheCheckCatchesACorruptedTorqueMax) {
    const auto map =
        std::make_shared<const FluxMap>(saturating_flux_map(2.0e-4, 6.0e-4, 0.078, 150.0, 0.1, 500.0, 650.0, 53));
    const MagnetFlux flux(*map, 0.0);
    SaturatedOptimalCurrent solver(map, 4);
    const double V_max = 0.95 * 355.0 / std::sqrt(3.0);
    for (const auto& [w_m, region] :
         {std::pair{100.0, Region::mtpa}, std::pair{600.0, Region::current_and_voltage_limit},
          std::pair{1200.0, Region::mtpv}}) {  // rad/s
        const OperatingLimits lim{4 * w_m, V_max, 500.0};
        const CurrentCommand good = solver.solve(1e6, lim, 0.012, 0.0, Recursion::optimal);
        ASSERT_EQ(good.region, region) << w_m;
        ASSERT_EQ(solver.last_check.finding, CheckFinding::passed) << w_m;
        ASSERT_FALSE(solver.last_check.searched_max) << w_m;

        fault_injection::top_scale() = 0.999;  // 0.1 % less current: inside both limits
        const CurrentCommand c = solver.solve(1e6, lim, 0.012, 0.0, Recursion::optimal);
        const CheckRecord found = solver.last_check;
        fault_injection::top_scale() = 1.0;
        EXPECT_TRUE(found.searched_max) << w_m;
        EXPECT_EQ(found.finding, CheckFinding::torque_max) << w_m;
        EXPECT_TRUE(found.replaced) << w_m;
        EXPECT_LT(found.rejected.torque_max, good.torque_max * (1.0 - 1e-5)) << w_m;
        // The robust search's T_max is the good one, and the command is its point.
        EXPECT_NEAR(c.torque_max, good.torque_max, 1e-7 * good.torque_max) << w_m;
        EXPECT_NEAR(6.0 * flux.reduced_torque(c.i_d, c.i_q), c.torque_max, 1e-7 * good.torque_max) << w_m;
    }
}
