// CurrentRegulator keeps the reference's flux between samples (the reference is held over a
// communication step): a regulator that has kept it must command, bit for bit, what a regulator
// with the same state but nothing kept commands, when the reference, the magnet temperature or
// the map changes.
#include <gtest/gtest.h>

#include <memory>

#include "control/current_regulator.hpp"
#include "flux_map_generators.hpp"
#include "machine/magnet_flux.hpp"

using namespace ipmsm;

namespace {

constexpr double kIMax = 500.0, kRs = 0.012, kPsiM = 0.078, kLd = 2.0e-4, kLq = 6.0e-4;
constexpr double kBandwidth = 2000.0, kH = 1e-4, kOmega = 800.0, kUdc = 355.0;

std::shared_ptr<const FluxMap> map_with_cross(double cross) {
    return std::make_shared<const FluxMap>(saturating_flux_map(kLd, kLq, kPsiM, 700.0, cross, kIMax, 1.3 * kIMax, 53));
}

// Steps `kept` (which has stepped before) and a regulator with kept's state but nothing kept
// from earlier samples, with the same arguments: the commands and the states must be equal.
void expect_same_as_fresh(CurrentRegulator& kept, double i_d_ref, double i_q_ref, const MagnetFlux& flux) {
    CurrentRegulator fresh(kBandwidth, kRs);
    fresh.state = kept.state;
    const double i_d = -40.0, i_q = 120.0;
    const VoltageCommand a = kept.step({i_d_ref, i_q_ref}, {i_d, i_q}, kOmega, kUdc, kH, flux);
    const VoltageCommand b = fresh.step({i_d_ref, i_q_ref}, {i_d, i_q}, kOmega, kUdc, kH, flux);
    EXPECT_EQ(a.u_d, b.u_d);
    EXPECT_EQ(a.u_q, b.u_q);
    EXPECT_EQ(kept.state.v.d, fresh.state.v.d);
    EXPECT_EQ(kept.state.v.q, fresh.state.v.q);
    EXPECT_EQ(kept.state.psi_ref.d, fresh.state.psi_ref.d);
    EXPECT_EQ(kept.state.psi_ref.q, fresh.state.psi_ref.q);
}

}  // namespace

TEST(CurrentRegulator, ReferenceFluxFollowsReferenceMagnetAndMap) {
    const auto map = map_with_cross(0.3), other = map_with_cross(0.6);
    CurrentRegulator reg(kBandwidth, kRs);
    const MagnetFlux cold(*map, 0.0), warm(*map, -0.006), other_cold(*other, 0.0);
    for (int k = 0; k < 3; ++k) reg.step({-50.0, 150.0}, {-40.0, 120.0}, kOmega, kUdc, kH, cold);  // kept
    SCOPED_TRACE("the same reference");
    expect_same_as_fresh(reg, -50.0, 150.0, cold);
    SCOPED_TRACE("a new reference");
    expect_same_as_fresh(reg, -80.0, 200.0, cold);
    SCOPED_TRACE("the magnet warmer, the same reference");
    expect_same_as_fresh(reg, -80.0, 200.0, warm);
    SCOPED_TRACE("another map, the same reference and magnet");
    expect_same_as_fresh(reg, -80.0, 200.0, other_cold);
}
