#include "flux_map_generators.hpp"

#include <cmath>
#include <string>

namespace ipmsm {

FluxMapTable linear_flux_map(double L_d, double L_q, double psi_m, double i_range, int n) {
    if (n < 2) throw FluxMapError("linear_flux_map: n = " + std::to_string(n) + " < 2");
    if (!(i_range > 0) || !std::isfinite(i_range) || !std::isfinite(L_d) || !std::isfinite(L_q) ||
        !std::isfinite(psi_m))
        throw FluxMapError("linear_flux_map: non-finite parameter or i_range <= 0");
    FluxMapTable t;
    t.i_d.resize(n);
    for (int k = 0; k < n; ++k)  // symmetric to the last bit; exactly 0 in the middle for odd n
        t.i_d[k] = i_range * static_cast<double>(2 * k - (n - 1)) / static_cast<double>(n - 1);
    t.i_q = t.i_d;
    t.psi_d.resize(static_cast<std::size_t>(n) * n);
    t.psi_q.resize(t.psi_d.size());
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j) {
            t.psi_d[static_cast<std::size_t>(k) * n + j] = L_d * t.i_d[j] + psi_m;
            t.psi_q[static_cast<std::size_t>(k) * n + j] = L_q * t.i_q[k];
        }
    return t;
}

FluxMapTable saturating_flux_map(double L_d, double L_q, double psi_m, double I_s, double cross, double I_ref,
                                 double i_range, int n) {
    FluxMapTable t = linear_flux_map(L_d, L_q, psi_m, i_range, n);
    for (int k = 0; k < n; ++k)
        for (int j = 0; j < n; ++j) {
            const double y = t.i_q[k] / I_ref, z = t.i_q[k] / I_s;
            t.psi_d[static_cast<std::size_t>(k) * n + j] =
                psi_m * (1.0 - cross * y * y / (1.0 + y * y)) + L_d * t.i_d[j];
            t.psi_q[static_cast<std::size_t>(k) * n + j] = L_q * t.i_q[k] / std::sqrt(1.0 + z * z);
        }
    return t;
}

}  // namespace ipmsm
