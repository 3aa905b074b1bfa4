// The flux map sampled on concentric current circles |i| = I_k = I_max k / K (k = 1..K) at N
// equally spaced angles: where the torque along a circle has its maxima, to bracket them before
// Newton polishes one (saturated_optimal_current.cpp). On a map whose q-axis flux levels off hard
// the torque along a circle has two maxima, and Newton from a linearised machine's point finds
// either; the samples say which one is the largest.
//
// The samples keep psi_d without the magnet's shift, which enters the torque linearly,
// T' = (psi_d + shift) i_q - psi_q i_d: one sampling serves every magnet temperature.
#pragma once

#include <vector>

#include "machine/flux_map.hpp"
#include "machine/machine.hpp"

namespace ipmsm {

class CurrentCircles {
public:
    static constexpr int kRadii = 32, kAngles = 128;

    struct Sample {
        double i_d, i_q, psi_d, psi_q;  // psi_d without the magnet shift
        double torque(double shift) const { return (psi_d + shift) * i_q - psi_q * i_d; }
    };

    CurrentCircles() = default;
    CurrentCircles(const FluxMap& map, double I_max);

    double I_max() const { return I_max_; }
    double radius(int k) const { return I_max_ * k / kRadii; }
    // Circle k = 1..K, angle j (any integer: taken modulo N).
    const Sample& at(int k, int j) const { return samples_[(k - 1) * kAngles + ((j % kAngles) + kAngles) % kAngles]; }
    // The angle of most s T' on circle k (s = +-1), at a magnet shift; with left_half, among the
    // angles with i_d <= 0 only (the tie convention of magnet-free machines, docs/controller.md).
    int best_angle(int k, double s, double shift, bool left_half = false) const;

private:
    double I_max_ = 0;
    std::vector<Sample> samples_;
};

}  // namespace ipmsm
