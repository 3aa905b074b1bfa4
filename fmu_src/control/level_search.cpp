#include "control/level_search.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

namespace ipmsm::level_search {
namespace {

// Rays cast around a candidate, per grid spacing of arc: a spline bends on the grid's scale.
constexpr double kRaysPerGridSpacing = 4.0;
constexpr int kMaxSubRays = 64;
// Candidates (local minima of r(theta), limit crossings) polished, best first.
constexpr int kMaxPolished = 4;
// The polish stops when the angle's bracket is below this (rad): r(theta) is flat at a
// minimum, so the current is then exact to rounding; on the voltage limit the point moves
// by I_max times this.
constexpr double kAngleTolerance = 1e-11;
constexpr int kMaxPolishIterations = 80;
// A ray's root is exact when the torque is within this (relative) of the target.
constexpr double kRootTolerance = 1e-13;
constexpr double kGolden = 0.38196601125010515;  // (3 - sqrt 5) / 2

struct Along {
    double T, dT;  // s T' and its derivative along the ray
    FluxPoint f;
};

// One point on the level curve: the ray's angle, radius and the voltage margin g = |v|^2 - V^2.
struct LevelPoint {
    double theta = 0, r = INFINITY, g = INFINITY;
    bool has_root = false;
    bool feasible() const { return has_root && g <= 0; }
};

class Search {
public:
    Search(const MagnetFlux& flux, const CurrentCircles& circles, double s, double T_red, const OperatingLimits& lim,
           double R_s, double resolution, bool left_half)
        : left_half_(left_half),
          flux_(flux),
          circles_(circles),
          s_(s),
          T_(T_red),
          lim_(lim),
          R_s_(R_s),
          res_(resolution),
          V2_(lim.V_max * lim.V_max * (1.0 + 1e-9)) {}

    Result run() {
        constexpr int K = CurrentCircles::kRadii, N = CurrentCircles::kAngles;
        const double shift = flux_.shift();
        // 1. One ray per circle angle, bracketed by the circles' samples (no evaluation).
        std::vector<LevelPoint> ray(N);
        for (int j = 0; j < N; ++j) {
            ray[j].theta = 2.0 * kPi * j / N;
            if (!allowed(ray[j].theta)) continue;
            double lo = 0.0, f_lo = 0.0;
            for (int k = 1; k <= K; ++k) {
                const double f = s_ * circles_.at(k, j).torque(shift);
                if (f >= T_) {
                    ray[j] = root(ray[j].theta, lo, circles_.radius(k), f_lo, f);
                    break;
                }
                lo = circles_.radius(k), f_lo = f;
            }
        }
        // 2. Candidates: local minima of r(theta) among feasible rays, and feasible rays next
        //    to infeasible ones (the voltage limit cuts the level curve between them).
        struct Candidate {
            int j, o;  // o == j: interior minimum; else the infeasible neighbour
            double r;
        };
        std::vector<Candidate> cands;
        for (int j = 0; j < N; ++j) {
            if (!ray[j].feasible()) continue;
            const LevelPoint &a = ray[(j + N - 1) % N], &b = ray[(j + 1) % N];
            if (ray[j].r <= a.r && ray[j].r <= b.r) cands.push_back({j, j, ray[j].r});
            for (int o : {(j + N - 1) % N, (j + 1) % N})
                if (ray[o].has_root && !ray[o].feasible()) cands.push_back({j, o, ray[j].r});
        }
        std::sort(cands.begin(), cands.end(), [](const Candidate& x, const Candidate& y) { return x.r < y.r; });
        Result best;
        for (int i = 0; i < static_cast<int>(cands.size()) && i < kMaxPolished; ++i) {
            const Candidate& c = cands[i];
            LevelPoint p;
            Region region;
            if (c.o == c.j) {
                p = interior_minimum(ray[(c.j + N - 1) % N], ray[c.j], ray[(c.j + 1) % N]);
                region = Region::mtpa;
            } else {
                p = on_voltage_limit(ray[c.j], ray[c.o]);
                region = Region::voltage_limit;
            }
            if (!p.feasible()) continue;
            const CurrentPoint q{p.r * std::cos(p.theta), p.r * std::sin(p.theta)};
            if (!best.found || better(q, best.point)) best.point = q, best.region = region, best.found = true;
        }
        best.evaluations = evaluations_;
        return best;
    }

private:
    // Less current, or as much within kTieTolerance and on the i_d <= 0 side (the tie convention).
    static bool better(const CurrentPoint& a, const CurrentPoint& b) {
        const double ra = std::hypot(a.i_d, a.i_q), rb = std::hypot(b.i_d, b.i_q);
        if (std::abs(ra - rb) <= kTieTolerance * std::max(ra, rb)) return a.i_d <= 0.0 && b.i_d > 0.0;
        return ra < rb;
    }

    // The angles searched: all, or i_d <= 0 only.
    bool allowed(double theta) const { return !left_half_ || std::cos(theta) <= 0.0; }

    Along along(double c, double sn, double r) {
        ++evaluations_;
        const double id = r * c, iq = r * sn;
        const FluxPoint f = flux_.eval(id, iq);
        const double Td = f.L_dd * iq - f.L_qd * id - f.psi_q, Tq = f.L_dq * iq + f.psi_d - f.L_qq * id;
        return {s_ * (f.psi_d * iq - f.psi_q * id), s_ * (Td * c + Tq * sn), f};
    }

    double voltage_margin(const FluxPoint& f, double id, double iq) const {
        const double vd = R_s_ * id - lim_.omega * f.psi_q, vq = R_s_ * iq + lim_.omega * f.psi_d;
        return vd * vd + vq * vq - V2_;
    }

    // The crossing of the level in [lo, hi] (f_lo < T <= f_hi): Newton kept inside the bracket.
    LevelPoint root(double theta, double lo, double hi, double f_lo, double f_hi) {
        const double c = std::cos(theta), sn = std::sin(theta);
        double r = lo + (T_ - f_lo) / (f_hi - f_lo) * (hi - lo);
        Along a{};
        for (int it = 0; it < 100; ++it) {
            a = along(c, sn, r);
            const double e = a.T - T_;
            (e < 0 ? lo : hi) = r;
            if (std::abs(e) <= kRootTolerance * T_ || hi - lo <= 1e-15 * lim_.I_max) break;
            double next = r - e / a.dT;
            if (!(next > lo && next < hi)) next = 0.5 * (lo + hi);
            r = next;
        }
        LevelPoint p;
        p.theta = theta, p.r = r, p.has_root = true;
        p.g = voltage_margin(a.f, r * c, r * sn);
        return p;
    }

    // The level's crossing on the ray at theta near radius `guess`: bracketed by steps of half the
    // map's resolution (the level curve moves little between neighbouring rays).
    LevelPoint level_at(double theta, double guess) {
        if (!allowed(theta)) return LevelPoint{theta, INFINITY, INFINITY, false};
        const double c = std::cos(theta), sn = std::sin(theta), step = 0.5 * res_;
        guess = std::clamp(guess, 0.0, lim_.I_max);
        double f = guess > 0 ? along(c, sn, guess).T : 0.0;
        double lo, hi, f_lo, f_hi;
        if (f >= T_) {
            hi = guess, f_hi = f;
            for (;;) {
                lo = std::max(0.0, hi - step);
                f_lo = lo > 0 ? along(c, sn, lo).T : 0.0;
                if (f_lo < T_) break;
                hi = lo, f_hi = f_lo;
            }
        } else {
            lo = guess, f_lo = f;
            for (;;) {
                if (lo >= lim_.I_max) return LevelPoint{theta, INFINITY, INFINITY, false};
                hi = std::min(lim_.I_max, lo + step);
                f_hi = along(c, sn, hi).T;
                if (f_hi >= T_) break;
                lo = hi, f_lo = f_hi;
            }
        }
        return root(theta, lo, hi, f_lo, f_hi);
    }

    // Rays between the neighbours at a fraction of the grid spacing, then golden section on the
    // best one's bracket; infeasible points count as infinite current.
    LevelPoint interior_minimum(const LevelPoint& a, const LevelPoint& m, const LevelPoint& b) {
        const double span = std::remainder(b.theta - a.theta, 2.0 * kPi);
        const double arc = std::abs(span) * m.r;
        const int n = std::clamp(static_cast<int>(std::ceil(arc * kRaysPerGridSpacing / res_)), 2, kMaxSubRays);
        std::vector<LevelPoint> sub(n + 1);
        int best = -1;
        double guess = a.has_root ? a.r : m.r;
        for (int i = 0; i <= n; ++i) {
            const double th = a.theta + span * i / n;
            sub[i] = level_at(th, guess);
            if (sub[i].has_root) guess = sub[i].r;
            if (sub[i].feasible() && (best < 0 || sub[i].r < sub[best].r)) best = i;
        }
        if (best < 0) return m;
        auto cost = [](const LevelPoint& p) { return p.feasible() ? p.r : INFINITY; };
        double x0 = sub[std::max(0, best - 1)].theta, x1 = sub[std::min(n, best + 1)].theta;
        if (x1 < x0) x1 += 2.0 * kPi;  // the bracket crosses theta = 0
        LevelPoint p = sub[best];
        LevelPoint u = level_at(x0 + kGolden * (x1 - x0), p.r), v = level_at(x1 - kGolden * (x1 - x0), p.r);
        for (int it = 0; it < kMaxPolishIterations && x1 - x0 > kAngleTolerance; ++it) {
            if (cost(u) <= cost(v)) {
                x1 = v.theta, v = u;
                u = level_at(x0 + kGolden * (x1 - x0), v.r);
            } else {
                x0 = u.theta, u = v;
                v = level_at(x1 - kGolden * (x1 - x0), u.r);
            }
        }
        for (const LevelPoint& q : {u, v})
            if (cost(q) < cost(p)) p = q;
        return p;
    }

    // Bisection on the angle between a feasible and an infeasible point of the level curve.
    LevelPoint on_voltage_limit(LevelPoint in, LevelPoint out) {
        double d = std::remainder(out.theta - in.theta, 2.0 * kPi);
        for (int it = 0; it < kMaxPolishIterations && std::abs(d) > kAngleTolerance; ++it) {
            d *= 0.5;
            const LevelPoint m = level_at(in.theta + d, in.r);
            if (m.feasible()) {
                in = m;
            } else if (!m.has_root) {
                break;
            }
            // else: the limit lies between in and m: the next halving looks there
        }
        return in;
    }

    const bool left_half_;
    const MagnetFlux& flux_;
    const CurrentCircles& circles_;
    const double s_, T_;
    const OperatingLimits& lim_;
    const double R_s_, res_, V2_;
    int evaluations_ = 0;
};

}  // namespace

double grid_resolution(const FluxMap& map) {
    const FluxMapTable& t = map.table();
    double h = INFINITY;
    for (const std::vector<double>* axis : {&t.i_d, &t.i_q})
        for (std::size_t k = 1; k < axis->size(); ++k) h = std::min(h, (*axis)[k] - (*axis)[k - 1]);
    return h;
}

Result least_current(const MagnetFlux& flux, const CurrentCircles& circles, double s, double T_red,
                     const OperatingLimits& lim, double R_s, double resolution_A, bool left_half) {
    const double res = std::clamp(resolution_A, 1e-6 * lim.I_max, lim.I_max / CurrentCircles::kRadii);
    return Search(flux, circles, s, T_red, lim, R_s, res, left_half).run();
}

}  // namespace ipmsm::level_search
