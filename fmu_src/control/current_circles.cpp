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
