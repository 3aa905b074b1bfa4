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
