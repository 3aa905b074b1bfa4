// Times ipmsm::solve_quartic (closed form, Ferrari) against Eigen's companion-matrix solver
// (Eigen::PolynomialSolver<double, 4>) on the same pre-generated quartics.
//
//   bench_quartic [count=100000] [repetitions=7]      (build type Release: -O3)
//
// Reports the best and median time per call over the repetitions, for several input mixes
// (random coefficients; four real roots; two real roots + complex pair; the controller's
// Case ii shape a4 y^4 + a2 y^2 + a1 y + a0). A checksum of all roots is printed so that the
// calls cannot be optimised away.
#include "numerics/quartic.hpp"

#include <unsupported/Eigen/Polynomials>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <random>
#include <vector>

namespace {

struct Quartic {
    double c[5];  // c[0] x^4 + ... + c[4]
};

using Clock = std::chrono::steady_clock;

std::vector<Quartic> make_set(int kind, int n, std::mt19937_64& rng) {
    std::uniform_real_distribution<double> u(-1.0, 1.0);
    std::vector<Quartic> v(static_cast<std::size_t>(n));
    for (auto& q : v) {
        switch (kind) {
            case 0:  // random coefficients
                for (double& x : q.c) x = u(rng);
                break;
            case 1: {  // four real roots
                const double r[4] = {u(rng), u(rng), u(rng), u(rng)};
                const double s1 = r[0] + r[1] + r[2] + r[3];
                const double s2 = r[0] * r[1] + r[0] * r[2] + r[0] * r[3] + r[1] * r[2] + r[1] * r[3] + r[2] * r[3];
                const double s3 = r[0] * r[1] * r[2] + r[0] * r[1] * r[3] + r[0] * r[2] * r[3] + r[1] * r[2] * r[3];
                const double s4 = r[0] * r[1] * r[2] * r[3];
                q = Quartic{{1.0, -s1, s2, -s3, s4}};
                break;
            }
            case 2: {  // two real roots and a complex pair
                const double r1 = u(rng), r2 = u(rng), re = u(rng), im = 0.05 + std::fabs(u(rng));
                const double p1 = -(r1 + r2), p0 = r1 * r2, s1 = -2 * re, s0 = re * re + im * im;
                q = Quartic{{1.0, p1 + s1, p0 + p1 * s1 + s0, p1 * s0 + p0 * s1, p0 * s0}};
                break;
            }
            default: {  // Case ii of the controller: no cubic term, physical-ish magnitudes
                const double a4 = 1e-8 * (1.0 + 0.5 * u(rng)), a2 = 1e-3 * u(rng);
                const double a1 = -0.5 * (1.0 + 0.5 * u(rng)), a0 = 50.0 * (1.0 + 0.5 * u(rng));
                q = Quartic{{a4, 0.0, a2, a1, a0}};
                break;
            }
        }
    }
    return v;
}

template <class F>
double time_per_call(const std::vector<Quartic>& set, int reps, F&& solve, double& checksum, double& median) {
    std::vector<double> t;
    for (int r = 0; r < reps; ++r) {
        double sum = 0.0;
        const auto t0 = Clock::now();
        for (const Quartic& q : set) sum += solve(q);
        const auto t1 = Clock::now();
        checksum += sum;
        t.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count() / static_cast<double>(set.size()));
    }
    std::sort(t.begin(), t.end());
    median = t[t.size() / 2];
    return t.front();
}

}  // namespace

int main(int argc, char** argv) {
    const int n = argc > 1 ? std::max(1, std::atoi(argv[1])) : 100000;
    const int reps = argc > 2 ? std::max(1, std::atoi(argv[2])) : 7;
    std::mt19937_64 rng(20240601);
    const char* names[] = {"random coefficients", "4 real roots", "2 real + complex pair", "controller Case ii"};
    std::printf("%d quartics per set, %d repetitions; ns per call (best / median)\n", n, reps);
    std::printf("%-24s %22s %22s %8s\n", "set", "ipmsm::solve_quartic", "Eigen PolynomialSolver", "ratio");
    double checksum = 0.0;
    for (int kind = 0; kind < 4; ++kind) {
        const std::vector<Quartic> set = make_set(kind, n, rng);
        double med_f = 0.0, med_e = 0.0;
        const double best_f = time_per_call(
            set, reps,
            [](const Quartic& q) {
                const ipmsm::RealRoots r = ipmsm::solve_quartic(q.c[0], q.c[1], q.c[2], q.c[3], q.c[4]);
                double s = r.count;
                for (int i = 0; i < r.count; ++i) s += r.root[i];
                return s;
            },
            checksum, med_f);
        // Eigen: companion matrix, balancing, real Schur; real roots picked as in the tests.
        const double best_e = time_per_call(
            set, reps,
            [](const Quartic& q) {
                Eigen::Matrix<double, 5, 1> p;
                for (int i = 0; i < 5; ++i) p[i] = q.c[4 - i];  // ascending powers
                Eigen::PolynomialSolver<double, 4> solver(p);
                double s = 0.0;
                for (int i = 0; i < 4; ++i)
                    if (std::fabs(solver.roots()[i].imag()) <= 1e-10 * std::abs(solver.roots()[i]))
                        s += 1.0 + solver.roots()[i].real();
                return s;
            },
            checksum, med_e);
        std::printf("%-24s %10.1f / %-9.1f %10.1f / %-9.1f %7.1fx\n", names[kind], best_f, med_f, best_e, med_e,
                    best_e / best_f);
    }
    std::printf("checksum %.17g\n", checksum);
    return 0;
}
