#include "control/max_torque_search.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace ipmsm::max_torque_search {
namespace {

// Samples of the circles searched around a candidate sample: its neighbours in radius and this
// many angles either side (the best angle moves little between neighbouring circles).
constexpr int kAngleWindow = 3;
// Candidates (local maxima of the sampled torque within the limits) refined, best first.
constexpr int kMaxRefined = 3;
// Angles per grid spacing of arc on a circle: a spline bends on the grid's scale.
constexpr double kAnglesPerGridSpacing = 4.0;
constexpr int kMinAngles = 8, kMaxAngles = 96;
// Golden section stops at these brackets: the angle (rad; at a maximum the torque is flat, on the
// voltage limit the point moves by I_max times this) and the radius (relative to I_max; H(r) is
// flat at an interior maximum, and the corner r = I_max is evaluated exactly).
constexpr double kAngleTolerance = 1e-10;
constexpr double kRadiusTolerance = 1e-5;
constexpr int kMaxGoldenIterations = 80;
constexpr double kGolden = 0.38196601125010515;  // (3 - sqrt 5) / 2

struct Point {
    double r = 0, theta = 0, T = -INFINITY;  // T: s T', -inf outside the limits
};

class Search {
public:
    Search(const MagnetFlux& flux, const CurrentCircles& circles, double s, const OperatingLimits& lim, double R_s,
           double resolution, bool left_half)
        : flux_(flux),
          circles_(circles),
          s_(s),
          lim_(lim),
          R_s_(R_s),
          res_(resolution),
          left_half_(left_half),
          V2_(lim.V_max * lim.V_max * (1.0 + 1e-9)) {}

    Result run() {
        constexpr int K = CurrentCircles::kRadii, N = CurrentCircles::kAngles;
        const double shift = flux_.shift();
        // 1. The samples within the limits (no evaluation: the circles keep their fluxes), each
        //    valued at the most torque of itself and of the voltage limit's crossings towards its
        //    neighbours outside it (g and T' interpolated linearly): a sample's own torque is off
        //    the limit's by the torque's gradient times its distance to the limit, which would rank
        //    the samples by that distance rather than by their place along the limit.
        std::vector<double> T((K + 1) * N, -INFINITY), g((K + 1) * N, INFINITY), own((K + 1) * N, -INFINITY);
        auto index = [&](int k, int j) { return k * N + ((j % N) + N) % N; };
        for (int k = 1; k <= K; ++k)
            for (int j = 0; j < N; ++j) {
                const CurrentCircles::Sample& x = circles_.at(k, j);
                const double vd = R_s_ * x.i_d - lim_.omega * x.psi_q;
                const double vq = R_s_ * x.i_q + lim_.omega * (x.psi_d + shift);
                if (!allowed(x.i_d)) continue;
                g[index(k, j)] = vd * vd + vq * vq - V2_;
                own[index(k, j)] = s_ * x.torque(shift);
            }
        for (int k = 1; k <= K; ++k)
            for (int j = 0; j < N; ++j) {
                const int i = index(k, j);
                if (!(g[i] <= 0)) continue;
                T[i] = own[i];
                for (const auto& [kk, jj] :
                     {std::pair{k - 1, j}, std::pair{k + 1, j}, std::pair{k, j - 1}, std::pair{k, j + 1}}) {
                    if (kk < 1 || kk > K) continue;
                    const int o = index(kk, jj);
                    if (!(g[o] > 0) || own[o] == -INFINITY) continue;
                    const double t = g[i] / (g[i] - g[o]);
                    T[i] = std::max(T[i], own[i] + t * (own[o] - own[i]));
                }
            }
        auto at = [&](int k, int j) { return T[index(k, j)]; };
        // 2. Candidates: samples within the limits whose neighbours (in radius and angle; outside
        //    the limits counting as -inf) have no more torque.
        struct Candidate {
            int k, j;
            double T;
        };
        std::vector<Candidate> cands;
        for (int k = 1; k <= K; ++k)
            for (int j = 0; j < N; ++j) {
                const double t = at(k, j);
                if (t == -INFINITY) continue;
                bool local_max = true;
                for (int dk = -1; dk <= 1 && local_max; ++dk)
                    for (int dj = -1; dj <= 1; ++dj) {
                        const int kk = k + dk;
                        if ((dk == 0 && dj == 0) || kk < 1 || kk > K) continue;
                        if (at(kk, j + dj) > t) {
                            local_max = false;
                            break;
                        }
                    }
                if (local_max) cands.push_back({k, j, t});
            }
        std::sort(cands.begin(), cands.end(), [](const Candidate& a, const Candidate& b) { return a.T > b.T; });
        // 3. Each refined: golden section in the radius between its neighbouring circles, the
        //    circle's best point within the limits at each radius; where that ends at the
        //    bracket's edge, the bracket moves on by a circle (the samples' estimates are off by
        //    the torque's curvature over a sample, which can put a candidate a circle or more from
        //    its maximum), and at the current limit the corner r = I_max is evaluated exactly.
        const double dtheta = 2.0 * kPi / N;
        for (int i = 0; i < static_cast<int>(cands.size()) && i < kMaxRefined; ++i) {
            int lo = cands[i].k - 1, hi = std::min(K, cands[i].k + 1);
            double theta = dtheta * cands[i].j;
            for (int moves = 0; moves <= K; ++moves) {
                const Point p = radial_maximum(lo, hi, theta);
                if (p.T == -INFINITY) break;
                theta = p.theta;
                const double edge = 2.0 * kRadiusTolerance * lim_.I_max;
                if (hi < K && p.r >= circles_.radius(hi) - edge)
                    ++lo, ++hi;
                else if (lo > 0 && p.r <= circles_.radius(lo) + edge)
                    --lo, --hi;
                else
                    break;
            }
        }
        Result out;
        out.found = best_.T > -INFINITY;
        out.point = {best_.r * std::cos(best_.theta), best_.r * std::sin(best_.theta)};
        out.torque = best_.T;
        out.evaluations = evaluations_;
        return out;
    }

private:
    // The most torque for radii between circles lo and hi, angles within kAngleWindow samples of
    // theta: golden section on H(r); at hi = K, H(I_max) exactly (the corner of the two limits).
    Point radial_maximum(int lo, int hi, double theta) {
        const double dtheta = 2.0 * kPi / CurrentCircles::kAngles;
        const double th0 = theta - kAngleWindow * dtheta, th1 = theta + kAngleWindow * dtheta;
        auto H = [&](double r) { return on_circle(r, th0, th1); };
        Point best;
        auto keep = [&](const Point& p) {
            if (p.T > best.T) best = p;
            return p;
        };
        if (hi == CurrentCircles::kRadii) keep(H(lim_.I_max));
        double x0 = circles_.radius(lo), x1 = circles_.radius(hi);
        Point u = keep(H(x0 + kGolden * (x1 - x0))), v = keep(H(x1 - kGolden * (x1 - x0)));
        for (int it = 0; it < kMaxGoldenIterations && x1 - x0 > kRadiusTolerance * lim_.I_max; ++it) {
            if (u.T >= v.T) {
                x1 = v.r, v = u;
                u = keep(H(x0 + kGolden * (x1 - x0)));
            } else {
                x0 = u.r, u = v;
                v = keep(H(x1 - kGolden * (x1 - x0)));
            }
        }
        return best;
    }

    bool allowed(double i_d) const { return !left_half_ || i_d <= 0.0; }

    void consider(const Point& p) {
        if (p.T > best_.T) best_ = p;
    }

    Point eval(double r, double theta) {
        ++evaluations_;
        const double id = r * std::cos(theta), iq = r * std::sin(theta);
        Point p{r, theta, -INFINITY};
        if (!allowed(id)) return p;
        const FluxPoint f = flux_.eval(id, iq);
        const double vd = R_s_ * id - lim_.omega * f.psi_q, vq = R_s_ * iq + lim_.omega * f.psi_d;
        if (vd * vd + vq * vq <= V2_) p.T = s_ * (f.psi_d * iq - f.psi_q * id);
        return p;
    }

    // H(r): the most torque on the circle of radius r between the angles th0 and th1 within the
    // limits: the arc sampled at a fraction of the grid spacing, then golden section on the best
    // sample's bracket (a point outside the limits counts as -inf, so that a maximum on the
    // voltage limit is approached from inside). Returns the point (T = -inf if none).
    Point on_circle(double r, double th0, double th1) {
        const int n = std::clamp(static_cast<int>(std::ceil(r * (th1 - th0) * kAnglesPerGridSpacing / res_)),
                                 kMinAngles, kMaxAngles);
        int best = -1;
        Point p;
        for (int i = 0; i <= n; ++i) {
            const Point q = eval(r, th0 + (th1 - th0) * i / n);
            if (q.T > p.T) p = q, best = i;
        }
        if (best < 0) return Point{r, 0.5 * (th0 + th1), -INFINITY};
        double x0 = th0 + (th1 - th0) * std::max(0, best - 1) / n, x1 = th0 + (th1 - th0) * std::min(n, best + 1) / n;
        Point u = eval(r, x0 + kGolden * (x1 - x0)), v = eval(r, x1 - kGolden * (x1 - x0));
        for (int it = 0; it < kMaxGoldenIterations && x1 - x0 > kAngleTolerance; ++it) {
            if (u.T >= v.T) {
                x1 = v.theta, v = u;
                u = eval(r, x0 + kGolden * (x1 - x0));
            } else {
                x0 = u.theta, u = v;
                v = eval(r, x1 - kGolden * (x1 - x0));
            }
        }
        for (const Point& q : {u, v})
            if (q.T > p.T) p = q;
        consider(p);
        return p;
    }

    const MagnetFlux& flux_;
    const CurrentCircles& circles_;
    const double s_;
    const OperatingLimits& lim_;
    const double R_s_, res_;
    const bool left_half_;
    const double V2_;
    Point best_;
    int evaluations_ = 0;
};

}  // namespace

Result max_torque(const MagnetFlux& flux, const CurrentCircles& circles, double s, const OperatingLimits& lim,
                  double R_s, double resolution_A, bool left_half) {
    const double res = std::clamp(resolution_A, 1e-6 * lim.I_max, lim.I_max / CurrentCircles::kRadii);
    return Search(flux, circles, s, lim, R_s, res, left_half).run();
}

}  // namespace ipmsm::max_torque_search
