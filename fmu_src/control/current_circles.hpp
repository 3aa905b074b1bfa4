// The flux map sampled on concentric current circles |i| = I_k = I_max k / K (k = 1..K) at N
// equally spaced angles: where the torque along a circle has its maxima, to bracket them before
// Newton polishes one (saturated_optimal_current.cpp). On a map whose q-axis flux levels off hard
// the torque along a circle has two maxima, and Newton from a linearised machine's point finds
// either; the samples say which one is the largest.
//
// The samples keep psi_d without the magnet's shift, which enters the torque linearly,
// T' = (psi_d + shift) i_q - psi_q i_d: one sampling serves every magnet temperature.
#pragma once

#include <algorithm>
#include <cmath>
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

    // A stretch of circle k: the samples j = m kArc .. (m + 1) kArc (both ends, the last one the
    // next stretch's first), or the whole circle; the ranges of its samples that bound their shaft
    // torque at any magnet shift (docs/spec/MATH.md, "Least-loss control": the scan's stretches).
    static constexpr int kArc = 8, kArcs = kAngles / kArc;
    static_assert(kAngles % kArc == 0, "the stretches tile each circle");
    struct Arc {
        double torque_lo = INFINITY, torque_hi = -INFINITY;  // T'_0 = psi_d i_q - psi_q i_d (no shift)
        double i_q_lo = INFINITY, i_q_hi = -INFINITY;
        double psi_d_lo = INFINITY, psi_d_hi = -INFINITY;    // without the shift
        double psi_q2_lo = INFINITY, psi_q2_hi = -INFINITY;  // psi_q^2
        double terms = 0.0;  // the largest |psi_d i_q| + |psi_q i_d|: the scale of T'_0's rounding
        void add(const Sample& x);
        // T' = T'_0 + shift i_q of every sample is within [torque_lo_at, torque_hi_at]
        double torque_lo_at(double shift) const { return torque_lo + std::min(shift * i_q_lo, shift * i_q_hi); }
        double torque_hi_at(double shift) const { return torque_hi + std::max(shift * i_q_lo, shift * i_q_hi); }
        // |psi|^2 = (psi_d + shift)^2 + psi_q^2 of every sample is within [flux_sq_lo, flux_sq_hi]
        double flux_sq_lo(double shift) const;
        double flux_sq_hi(double shift) const;
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
    // Stretch m = 0..kArcs-1 of circle k = 1..K; the whole circle k.
    const Arc& arc(int k, int m) const { return arcs_[(k - 1) * kArcs + m]; }
    const Arc& whole(int k) const { return wholes_[k - 1]; }

private:
    double I_max_ = 0;
    std::vector<Sample> samples_;
    std::vector<Arc> arcs_, wholes_;
};

}  // namespace ipmsm
