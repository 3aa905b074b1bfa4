#include "control/current_circles.hpp"

#include <cmath>

namespace ipmsm {

CurrentCircles::CurrentCircles(const FluxMap& map, double I_max) : I_max_(I_max) {
    samples_.reserve(static_cast<std::size_t>(kRadii) * kAngles);
    for (int k = 1; k <= kRadii; ++k) {
        for (int j = 0; j < kAngles; ++j) {
            const double a = 2.0 * kPi * j / kAngles, i_d = radius(k) * std::cos(a), i_q = radius(k) * std::sin(a);
            const FluxPoint f = map.eval(i_d, i_q);
            samples_.push_back({i_d, i_q, f.psi_d, f.psi_q});
        }
    }
    arcs_.reserve(static_cast<std::size_t>(kRadii) * kArcs);
    wholes_.resize(kRadii);
    for (int k = 1; k <= kRadii; ++k) {
        for (int m = 0; m < kArcs; ++m) {
            Arc a;
            for (int j = m * kArc; j <= (m + 1) * kArc; ++j) a.add(at(k, j));
            arcs_.push_back(a);
        }
        for (int j = 0; j < kAngles; ++j) wholes_[k - 1].add(at(k, j));
    }
}

void CurrentCircles::Arc::add(const Sample& x) {
    const double T = x.psi_d * x.i_q - x.psi_q * x.i_d, q2 = x.psi_q * x.psi_q;
    torque_lo = std::min(torque_lo, T), torque_hi = std::max(torque_hi, T);
    i_q_lo = std::min(i_q_lo, x.i_q), i_q_hi = std::max(i_q_hi, x.i_q);
    psi_d_lo = std::min(psi_d_lo, x.psi_d), psi_d_hi = std::max(psi_d_hi, x.psi_d);
    psi_q2_lo = std::min(psi_q2_lo, q2), psi_q2_hi = std::max(psi_q2_hi, q2);
    terms = std::max(terms, std::abs(x.psi_d * x.i_q) + std::abs(x.psi_q * x.i_d));
}

double CurrentCircles::Arc::flux_sq_lo(double shift) const {
    const double lo = psi_d_lo + shift, hi = psi_d_hi + shift;  // psi_d + shift within [lo, hi]
    const double d2 = lo > 0.0 ? lo * lo : hi < 0.0 ? hi * hi : 0.0;
    return d2 + psi_q2_lo;
}

double CurrentCircles::Arc::flux_sq_hi(double shift) const {
    const double lo = psi_d_lo + shift, hi = psi_d_hi + shift;
    return std::max(lo * lo, hi * hi) + psi_q2_hi;
}

int CurrentCircles::best_angle(int k, double s, double shift, bool left_half) const {
    int best = kAngles / 2;
    double T_best = -INFINITY;
    for (int j = 0; j < kAngles; ++j) {
        if (left_half && at(k, j).i_d > 0) continue;
        const double T = s * at(k, j).torque(shift);
        if (T > T_best) T_best = T, best = j;
    }
    return best;
}

}  // namespace ipmsm
