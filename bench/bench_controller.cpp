// ns per call of the current-command computation, side by side in one run:
//   Ferrari on a linear machine; recursion 1 and 2 on the default flux map, recursion 2 on a
//   strongly saturating one; the 2-D tables;
//   Eigen's companion-matrix solver on the same quartic; a Newton-Lagrange iteration from a
//   fixed start (the online approach the paper replaced).
// Saturated cases are timed two ways: "trajectory" (consecutive calls along a smooth
// torque/speed ramp, as in a drive, warm starts) and "random" (every call a new operating point).
//
// Then recursion 2 with its command check on each map given with --map (the corpus of
// tests/python/map_corpus.py: `python tests/python/map_corpus.py --bench` writes its maps and
// runs this with them): every call timed on its own, median and 99th percentile.
//
// Usage: build/bin/bench_controller [flux_map.csv] [--map NAME CSV POLE_PAIRS R_S I_MAX U_DC W_M_MAX]...
//        [--corpus-only | --least-loss-only]  (the corpus rows alone; or only their least-loss rows)
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <ctime>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include <unsupported/Eigen/Polynomials>

#include "control/least_loss.hpp"
#include "control/linear_optimal_current.hpp"
#include "control/map_newton.hpp"
#include "control/saturated_optimal_current.hpp"
#include "control/torque_table.hpp"
#include "flux_map_generators.hpp"
#include "numerics/quartic.hpp"
#include "source_tree.hpp"

using namespace ipmsm;
using Clock = std::chrono::steady_clock;

namespace {

constexpr int kPolePairs = 4;
constexpr double kUdc = 355.0, kIMax = 500.0, kRs = 0.012;
const double kVMax = 0.95 * kUdc / std::sqrt(3.0);
constexpr double kWmMax = 1256.6370614359173;  // 12 000 r/min
volatile double g_sink;

struct Op {
    double T, w_m;
};

std::vector<Op> random_ops(int n, unsigned seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<double> u(0, 1);
    std::vector<Op> v(n);
    for (auto& o : v) o = {(2 * u(rng) - 1) * 320.0, (2 * u(rng) - 1) * kWmMax};
    return v;
}

// A drive-like trajectory: torque and speed ramp smoothly, one call per 100 us.
std::vector<Op> trajectory_ops(int n) {
    std::vector<Op> v(n);
    for (int k = 0; k < n; ++k) {
        const double t = 1e-4 * k;
        v[k] = {250.0 * std::sin(2 * M_PI * 0.7 * t), kWmMax * (0.5 + 0.45 * std::sin(2 * M_PI * 0.13 * t))};
    }
    return v;
}

// ns per call, best of `repeats` runs over ops. Independent calls (the default) overlap in the
// CPU as far as its window allows; Chained makes each call's inputs depend on the previous
// result (by a term that is zero, which the CPU cannot know): the latency of one call.
template <bool Chained = false, class F>
double ns_per_call(const std::vector<Op>& ops, int repeats, F&& f) {
    double best = 1e300;
    for (int r = 0; r < repeats; ++r) {
        double sink = 0;
        const auto t0 = Clock::now();
        for (const Op& o : ops) {
            if constexpr (Chained) {
                const double zero = sink * 0.0;
                sink = std::min(sink + f(Op{o.T + zero, o.w_m + zero}), 1e300);
            } else {
                sink += f(o);
            }
        }
        const auto t1 = Clock::now();
        g_sink = sink;
        best = std::min(best, std::chrono::duration<double, std::nano>(t1 - t0).count() / ops.size());
    }
    return best;
}

void row(const char* name, double ns, const char* note = "") { std::printf("%-58s %9.1f ns  %s\n", name, ns, note); }

}  // namespace

struct CorpusMap {
    std::string name, path;
    int pole_pairs;
    double R_s, I_max, u_dc, w_m_max;
};

// Recursion 2 with the check on one map: each call timed alone (steady_clock, some 20 ns of its
// own), random operating points in four quadrants up to 1.3 times the zero-speed peak and the top
// speed, and a drive-like trajectory; the first call (the circles' sampling) left out.
void corpus_rows(const CorpusMap& c) {
    const auto map = std::make_shared<const FluxMap>(read_flux_map(c.path));
    const double V_max = 0.95 * c.u_dc / std::sqrt(3.0);
    SaturatedOptimalCurrent solver(map, c.pole_pairs);
    const double T_peak = solver.solve(1e12, {0.0, V_max, c.I_max}, c.R_s, 0.0, Recursion::optimal).torque_max;
    const int n = 100000;
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> u(0, 1);
    std::vector<Op> rnd(n), traj(n);
    for (auto& o : rnd) o = {(2 * u(rng) - 1) * 1.3 * T_peak, (2 * u(rng) - 1) * c.w_m_max};
    for (int k = 0; k < n; ++k) {
        const double t = 1e-4 * k;
        traj[k] = {0.9 * T_peak * std::sin(2 * M_PI * 0.7 * t),
                   c.w_m_max * (0.5 + 0.45 * std::sin(2 * M_PI * 0.13 * t))};
    }
    for (const auto& [label, ops] : {std::pair{"random", &rnd}, std::pair{"trajectory", &traj}}) {
        std::vector<double> ns(ops->size());
        long failed = 0, searched = 0;
        for (std::size_t k = 0; k < ops->size(); ++k) {
            const Op& o = (*ops)[k];
            const auto t0 = Clock::now();
            const auto cmd = solver.solve(o.T, {c.pole_pairs * o.w_m, V_max, c.I_max}, c.R_s, 0.0, Recursion::optimal);
            ns[k] = std::chrono::duration<double, std::nano>(Clock::now() - t0).count();
            g_sink = cmd.i_d;
            failed += solver.last_check.finding != CheckFinding::passed;
            searched += solver.last_check.searched_max;
        }
        std::sort(ns.begin(), ns.end());
        char name[96], note[160];
        std::snprintf(name, sizeof name, "recursion 2 + check, %s, %s", c.name.c_str(), label);
        std::snprintf(note, sizeof note,
                      "median; p99 %.0f ns; %ld of %zu failed the check, T_max searched %ld; budget <= 1500 ns",
                      ns[ns.size() * 99 / 100], failed, ns.size(), searched);
        row(name, ns[ns.size() / 2], note);
    }
}

// The calling thread's CPU time, ns: what a loaded machine's preemptions leave out of a row's mean.
double thread_cpu_ns() {
    timespec t{};
    clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
    return 1e9 * static_cast<double>(t.tv_sec) + static_cast<double>(t.tv_nsec);
}

// Least loss (objective 1, control/least_loss.hpp) with its check on one map: the least-current
// solver's T_max (the seed of the shaft torque's) and the least-loss solve, each call timed alone,
// the same operating points as corpus_rows. The loss model: the default motor's iron-loss fit and
// the default inverter (the timing does not depend on the coefficients' values, only on alpha).
void least_loss_rows(const CorpusMap& c) {
    const auto map = std::make_shared<const FluxMap>(read_flux_map(c.path));
    const double V_max = 0.95 * c.u_dc / std::sqrt(3.0);
    SaturatedOptimalCurrent solver(map, c.pole_pairs);
    LeastLoss least_loss(map, c.pole_pairs, solver.magnet_free());
    const MagnetFlux flux(*map, 0.0);
    const IronLossModel iron{1.06664735685, 2.0, 0.00581807649193, 0.0780669432093};
    const InverterParams inverter{};
    const double T_peak = solver.solve(1e12, {0.0, V_max, c.I_max}, c.R_s, 0.0, Recursion::optimal).torque_max;
    const int n = 20000;
    std::mt19937_64 rng(11);
    std::uniform_real_distribution<double> u(0, 1);
    std::vector<Op> rnd(n), traj(n);
    for (auto& o : rnd) o = {(2 * u(rng) - 1) * 1.3 * T_peak, (2 * u(rng) - 1) * c.w_m_max};
    for (int k = 0; k < n; ++k) {
        const double t = 1e-4 * k;
        traj[k] = {0.9 * T_peak * std::sin(2 * M_PI * 0.7 * t),
                   c.w_m_max * (0.5 + 0.45 * std::sin(2 * M_PI * 0.13 * t))};
    }
    for (const auto& [label, ops] : {std::pair{"random", &rnd}, std::pair{"trajectory", &traj}}) {
        std::vector<double> ns(ops->size());
        long failed = 0, searched = 0;
        const double cpu0 = thread_cpu_ns();
        for (std::size_t k = 0; k < ops->size(); ++k) {
            const Op& o = (*ops)[k];
            const OperatingLimits lim{c.pole_pairs * o.w_m, V_max, c.I_max};
            const auto t0 = Clock::now();
            const DriveLoss loss(iron, inverter, c.pole_pairs, o.w_m, c.R_s, c.u_dc);
            const CurrentCommand top = solver.solve(o.T < 0 ? -1e30 : 1e30, lim, c.R_s, 0.0, Recursion::optimal);
            const CurrentCommand em = solver.solve(o.T, lim, c.R_s, 0.0, Recursion::optimal);
            const CurrentPoint hint{em.i_d, em.i_q};
            const LeastLossResult r = least_loss.solve(o.T, lim, flux, loss, top, &hint);
            ns[k] = std::chrono::duration<double, std::nano>(Clock::now() - t0).count();
            g_sink = r.cmd.i_d;
            failed += !r.check_passed;
            searched += r.searched;
        }
        const double cpu_mean = (thread_cpu_ns() - cpu0) / static_cast<double>(ops->size());
        std::sort(ns.begin(), ns.end());
        char name[96], note[200];
        std::snprintf(name, sizeof name, "least loss + check, %s, %s", c.name.c_str(), label);
        std::snprintf(note, sizeof note,
                      "median; p99 %.0f ns; thread CPU %.0f ns/call (mean); %ld of %zu failed the check, searched "
                      "%ld; target <= 2000",
                      ns[ns.size() * 99 / 100], cpu_mean, failed, ns.size(), searched);
        row(name, ns[ns.size() / 2], note);
    }
}

int main(int argc, char** argv) {
    std::vector<CorpusMap> corpus;
    bool least_loss_only = false;
    std::string path = ipmsm::source_path("fmu_src/resources/ev_ipmsm_default.csv");
    for (int a = 1; a < argc; ++a) {
        const std::string arg = argv[a];
        if (arg == "--map" && a + 7 < argc) {
            corpus.push_back({argv[a + 1], argv[a + 2], std::atoi(argv[a + 3]), std::atof(argv[a + 4]),
                              std::atof(argv[a + 5]), std::atof(argv[a + 6]), std::atof(argv[a + 7])});
            a += 7;
        } else if (arg == "--corpus-only") {
            path.clear();
        } else if (arg == "--least-loss-only") {
            path.clear();
            least_loss_only = true;
        } else {
            path = arg;
        }
    }
    if (path.empty()) {
        if (!least_loss_only)
            for (const CorpusMap& c : corpus) corpus_rows(c);
        for (const CorpusMap& c : corpus) least_loss_rows(c);
        return 0;
    }
    auto map = std::make_shared<const FluxMap>(read_flux_map(path));
    const int N = 200000, R = 5;
    const auto rnd = random_ops(N, 7);
    const auto traj = trajectory_ops(N);
    std::printf("bench_controller: %d calls per case, best of %d runs; map %s\n\n", N, R, path.c_str());

    // Linear machine: the default map's nominal (unsaturated) parameters.
    const SaturatedOptimalCurrent probe(map, kPolePairs);
    const LinearMachine lin = probe.nominal_machine(kRs, 0.0);
    linear::CommandSolver linear_solver(kPolePairs);
    auto linear_call = [&](const Op& o) {
        const auto c = linear_solver(lin, o.T, {kPolePairs * o.w_m, kVMax, kIMax});
        return c.i_d + c.i_q;
    };
    auto linear_free_call = [&](const Op& o) {
        const auto c = linear::optimal_current(lin, kPolePairs, o.T, {kPolePairs * o.w_m, kVMax, kIMax});
        return c.i_d + c.i_q;
    };
    row("Ferrari, linear machine (clamp + MTPA/Case ii), trajectory", ns_per_call(traj, R, linear_call),
        "budget <= 300 ns");
    row("Ferrari, linear machine (clamp + MTPA/Case ii), random", ns_per_call(rnd, R, linear_call), "budget <= 300 ns");
    // The same, split by where the operating point is.
    // The nominal (unsaturated) machine's base speed is about 2000 r/min at 500 A.
    std::vector<Op> low, high;
    for (const Op& o : rnd) (std::abs(o.w_m) < 1500 * M_PI / 30 ? low : high).push_back(o);
    row("  ... below 1500 r/min (MTPA region: 1 quartic)", ns_per_call(low, R, linear_call));
    row("  ... above 1500 r/min (field weakening: 2 to 4 quartics)", ns_per_call(high, R, linear_call));
    // The same calls in an order that makes the branches predictable (speed in 20 rad/s bins, then
    // torque): what mispredicted branches cost on random operating points.
    std::vector<Op> high_sorted = high;
    std::sort(high_sorted.begin(), high_sorted.end(), [](const Op& a, const Op& b) {
        const int bin_a = static_cast<int>(std::abs(a.w_m) / 20), bin_b = static_cast<int>(std::abs(b.w_m) / 20);
        return bin_a != bin_b ? bin_a < bin_b : std::abs(a.T) < std::abs(b.T);
    });
    row("  ... above 1500 r/min, sorted by speed, then torque", ns_per_call(high_sorted, R, linear_call));
    row("  ... random, a new solver per call (linear::optimal_current)", ns_per_call(rnd, R, linear_free_call));

    // One quartic, Ferrari vs Eigen's companion matrix: the Case i quartic of each operating point.
    const double dL = lin.L_d - lin.L_q;
    auto ferrari_quartic = [&](const Op& o) {
        const double Tr = std::abs(o.T) / (1.5 * kPolePairs) + 1.0;
        return solve_quartic(dL * dL, 0, 0, lin.psi_m * Tr, -Tr * Tr).root[0];
    };
    auto eigen_quartic = [&](const Op& o) {
        const double Tr = std::abs(o.T) / (1.5 * kPolePairs) + 1.0;
        Eigen::Matrix<double, 5, 1> c;
        c << -Tr * Tr, lin.psi_m * Tr, 0, 0, dL * dL;
        Eigen::PolynomialSolver<double, 4> s(c);
        return s.roots()[0].real();
    };
    row("one Case i quartic: Ferrari, general robust solver", ns_per_call(rnd, R, ferrari_quartic));
    auto ferrari_depressed = [&](const Op& o) {
        const double Tr = std::abs(o.T) / (1.5 * kPolePairs) + 1.0, k = 1.0 / (dL * dL);
        return solve_depressed_quartic(0, lin.psi_m * Tr * k, -Tr * Tr * k).root[0];
    };
    row("one Case i quartic: Ferrari, depressed fast path (used online)", ns_per_call(rnd, R, ferrari_depressed));
    row("one Case i quartic: Eigen companion matrix (PolynomialSolver)", ns_per_call(rnd, R, eigen_quartic));
    row("  ... latency of the depressed fast path (calls chained)", ns_per_call<true>(rnd, R, ferrari_depressed));
    row("  ... latency of the linear machine above 1500 r/min (calls chained)",
        ns_per_call<true>(high, R, linear_call));

    // Newton-Lagrange on the linear machine from a fixed start (no Ferrari seed), MTPA only.
    const auto lin_map = std::make_shared<const FluxMap>(linear_flux_map(lin.L_d, lin.L_q, lin.psi_m, 900.0, 7));
    const MagnetFlux lin_flux(*lin_map, 0.0);
    int nl_fail = 0;
    auto newton_lagrange = [&](const Op& o) {
        const map_newton::Problem P{
            map_newton::System::mtpa, 0.0, kRs, std::abs(o.T) / (1.5 * kPolePairs) + 1.0, kVMax, kIMax};
        const auto r = map_newton::solve(lin_flux, P, -0.3 * kIMax, 0.6 * kIMax, 50, 1e-6, 50.0);
        nl_fail += !r.converged;
        return r.i_d + r.i_q;
    };
    row("Newton-Lagrange MTPA, linear machine, fixed start", ns_per_call(rnd, R, newton_lagrange));

    // Saturated: recursion 1 and 2 on the map, and recursion 2 on a strongly saturating map (the
    // default motor's nominal inductances, psi_q levelling off at I_s = 0.3 I_max, 10 % cross-
    // saturation): the torque along the current circle has two maxima.
    const auto saturating = std::make_shared<const FluxMap>(
        saturating_flux_map(lin.L_d, lin.L_q, lin.psi_m, 0.3 * kIMax, 0.1, kIMax, 1.4 * kIMax, 57));
    struct Case {
        const char* map_name;
        std::shared_ptr<const FluxMap> map;
        Recursion mode;
    };
    const Case cases[] = {{"default map", map, Recursion::apparent},
                          {"default map", map, Recursion::optimal},
                          {"saturating map (I_s = 0.3 I_max)", saturating, Recursion::optimal}};
    for (const auto& [label, ops] : {std::pair{"trajectory", &traj}, std::pair{"random", &rnd}}) {
        for (const Case& k : cases) {
            SaturatedOptimalCurrent solver(k.map, kPolePairs);
            long iters = 0;
            auto call = [&](const Op& o) {
                const auto c = solver.solve(o.T, {kPolePairs * o.w_m, kVMax, kIMax}, kRs, 0.0, k.mode);
                iters += c.iterations;
                return c.i_d + c.i_q;
            };
            const double ns = ns_per_call(*ops, R, call);
            char name[96], note[64];
            std::snprintf(name, sizeof name, "Ferrari + recursion %d, %s, %s", static_cast<int>(k.mode), k.map_name,
                          label);
            std::snprintf(note, sizeof note, "%.2f iterations/call%s", double(iters) / (R * ops->size()),
                          k.mode == Recursion::optimal ? ", budget <= 1500 ns" : "");
            row(name, ns, note);
        }
    }
    {
        // A new magnet temperature every call: the circles' maxima are found again each time.
        SaturatedOptimalCurrent solver(map, kPolePairs);
        int n = 0;
        auto call = [&](const Op& o) {
            const auto c =
                solver.solve(o.T, {kPolePairs * o.w_m, kVMax, kIMax}, kRs, 1e-6 * (++n % 1000), Recursion::optimal);
            return c.i_d + c.i_q;
        };
        row("  ... recursion 2, default map, random, a new magnet temperature every call", ns_per_call(rnd, 1, call));
        const auto t0 = Clock::now();
        SaturatedOptimalCurrent fresh(map, kPolePairs);
        g_sink = fresh.solve(100.0, {0.0, kVMax, kIMax}, kRs, 0.0, Recursion::optimal).i_d;
        row("  ... recursion 2, the first call (samples the map on the current circles)",
            std::chrono::duration<double, std::nano>(Clock::now() - t0).count());
    }

    // 2-D tables, 41 x 41.
    for (TableAxis axis : {TableAxis::speed, TableAxis::flux}) {
        TableSpec spec;
        spec.axis = axis;
        spec.u_dc = kUdc;
        spec.I_max = kIMax;
        spec.R_s = kRs;
        spec.w_m_max = kWmMax;
        const TorqueTable table(SaturatedOptimalCurrent(map, kPolePairs), spec);
        auto call = [&](const Op& o) {
            const auto c = table.lookup(o.T, o.w_m, kVMax);
            return c.i_d + c.i_q;
        };
        char name[96];
        std::snprintf(name, sizeof name, "2-D table 41x41 over torque x %s (%zu bytes), random",
                      axis == TableAxis::speed ? "speed" : "V_max/omega", table.bytes());
        row(name, ns_per_call(rnd, R, call));
    }
    if (nl_fail) std::printf("\nNewton-Lagrange did not converge in %d calls\n", nl_fail);
    for (const CorpusMap& c : corpus) corpus_rows(c);
    for (const CorpusMap& c : corpus) least_loss_rows(c);
    return 0;
}
