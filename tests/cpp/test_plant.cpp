// The IpmsmPlant's physics, CVODE wrapper and FMI-free model (plant/): closed-form agreement on a
// linear map, exactness of copies and restored states (bit-identical), CVODE failures as
// exceptions with CVODE's message and the state unchanged, initial outputs, refused maps and
// parameters leaving the model unchanged.
#include <gtest/gtest.h>

#include <unsupported/Eigen/MatrixFunctions>

#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include "cvode_integrator.hpp"
#include "flux_map_generators.hpp"
#include "freewheel_integrator.hpp"
#include "inverter_state.hpp"
#include "ipmsm_ode.hpp"
#include "linear_flow.hpp"
#include "machine/flux_map.hpp"
#include "machine/inverse_flux_map.hpp"
#include "plant_model.hpp"
#include "source_tree.hpp"
#include "state_stream.hpp"

using namespace ipmsm;

namespace {

const std::string kResources = ipmsm::source_path("fmu_src/resources");
const std::string kDefaultMap = kResources + "/ev_ipmsm_default.csv";

std::string temp_file(const std::string& name, const std::string& text) {
    std::string d = testing::TempDir();
    if (d.empty() || d.back() != '/') d += '/';
    d += "ipmsm_plant_test_" + std::to_string(::getpid());
    std::filesystem::create_directories(d);
    const std::string path = d + "/" + name;
    std::ofstream(path) << text;
    return path;
}

// The contract's CSV of a flux map table.
std::string csv_of(const FluxMapTable& t) {
    std::ostringstream os;
    os.precision(17);
    os << "i_d,i_q,psi_d,psi_q\n";
    for (std::size_t k = 0; k < t.i_q.size(); ++k)
        for (std::size_t j = 0; j < t.i_d.size(); ++j)
            os << t.i_d[j] << "," << t.i_q[k] << "," << t.psi_d[k * t.i_d.size() + j] << ","
               << t.psi_q[k * t.i_d.size() + j] << "\n";
    return os.str();
}

bool same_bits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

struct Linear {
    double L_d = 0.25e-3, L_q = 0.6e-3, psi_m = 0.08, R = 0.05;
};

// The closed-form solution of the linear dq equations over one interval with u held:
// psi(t + h) = psi_ss + exp(A h) (psi(t) - psi_ss).
Eigen::Vector2d linear_step(const Linear& m, double omega, double u_d, double u_q, const Eigen::Vector2d& psi,
                            double h) {
    Eigen::Matrix2d A;
    A << -m.R / m.L_d, omega, -omega, -m.R / m.L_q;
    const Eigen::Vector2d b(u_d + m.R * m.psi_m / m.L_d, u_q);
    const Eigen::Vector2d ss = -A.inverse() * b;
    const Eigen::Matrix2d E = (A * h).exp();
    return ss + E * (psi - ss);
}

fmi::Context context_with(std::vector<std::string>* warnings = nullptr) {
    fmi::Context c;
    c.instance_name = "test";
    c.resource_dir = kResources;
    c.log_info = [](const std::string&) {};
    c.log_warning = [warnings](const std::string& m) {
        if (warnings) warnings->push_back(m);
    };
    return c;
}

// Inputs for step k of a test run: voltage steps around the back-EMF at a given speed.
void inputs(PlantModel& m, int k, double w_m) {
    m.w_m = w_m;
    m.u_d = (k / 20) % 2 == 0 ? -10.0 : -25.0;
    m.u_q = ((k / 20) % 2 == 0 ? 8.0 : -4.0) + 0.312 * w_m;
}

std::vector<double> outputs(const PlantModel& m) {
    return {m.i_d, m.i_q, m.psi_d, m.psi_q, m.T_e, m.T_shaft, m.P_elec, m.P_mech, m.P_cu, m.P_fe};
}

}  // namespace

// LinearFlow against Eigen's Pade matrix exponential in long double of the augmented matrix
// [[A, I], [0, 0]] tau, whose exponential is [[exp(tau A), P(tau)], [0, I]]: every regime the
// closed forms switch between (rotation, real eigenvalues, a singular and a zero A, tiny and
// long steps, near-degenerate eigenvalues).
TEST(LinearFlow, MatchesTheAugmentedMatrixExponential) {
    const double G[4] = {4.8e3, -3e2, -2e2, 1.7e3};  // di/dpsi of a saturated, non-reciprocal map, 1/H
    struct Case {
        double R, omega;
    };
    for (const Case c :
         {Case{0.012, 5026.5}, Case{0.05, 0.0}, Case{0.0, 0.0}, Case{0.0, 1e-3}, Case{3.0, 200.0}, Case{0.012, 1.3}}) {
        const double A[4] = {-c.R * G[0], -c.R * G[1] + c.omega, -c.R * G[2] - c.omega, -c.R * G[3]};
        const LinearFlow flow(A);
        for (double tau : {1e-12, 1e-7, 3e-5, 1e-4, 1e-3, 1e-2}) {
            Eigen::Matrix<long double, 4, 4> M = Eigen::Matrix<long double, 4, 4>::Zero();
            for (int r = 0; r < 2; ++r) {
                for (int k = 0; k < 2; ++k) M(r, k) = static_cast<long double>(A[2 * r + k]) * tau;
                M(r, 2 + r) = tau;
            }
            const Eigen::Matrix<long double, 4, 4> X
            = M.exp();
            double E[4], Ei[4], P[4];
            flow.exp(tau, E, Ei);
            flow.integral(tau, E, P);
            double e_err = 0, p_err = 0, inv_err = 0, e_max = 0, p_max = 0, ei_max = 0;
            for (int r = 0; r < 2; ++r)
                for (int k = 0; k < 2; ++k) {
                    e_err = std::max(e_err, std::abs(E[2 * r + k] - static_cast<double>(X(r, k))));
                    p_err = std::max(p_err, std::abs(P[2 * r + k] - static_cast<double>(X(r, 2 + k))));
                    e_max = std::max(e_max, std::abs(E[2 * r + k]));
                    p_max = std::max(p_max, std::abs(P[2 * r + k]));
                    ei_max = std::max(ei_max, std::abs(Ei[2 * r + k]));
                    const double id = E[2 * r] * Ei[k] + E[2 * r + 1] * Ei[2 + k];
                    inv_err = std::max(inv_err, std::abs(id - (r == k ? 1.0 : 0.0)));
                }
            EXPECT_LT(e_err, 1e-14 * e_max) << "R " << c.R << " omega " << c.omega << " tau " << tau;
            EXPECT_LT(p_err, 1e-13 * p_max) << "R " << c.R << " omega " << c.omega << " tau " << tau;
            EXPECT_LT(inv_err, 1e-14 * e_max * ei_max) << "R " << c.R << " omega " << c.omega << " tau " << tau;
        }
    }
}

TEST(PlantOde, LinearMapMatchesClosedForm) {
    // R = 0.05 Ohm: the linearised formulation (exact on a linear map); R = 3 Ohm with 1 ms steps:
    // electrical time constants of 0.08 and 0.2 ms, the stiff case integrated directly.
    for (const auto& [R, h, tol] : {std::tuple{0.05, 1e-4, 1e-11}, {3.0, 1e-3, 1e-11}, {0.05, 1e-4, 1e-6}}) {
        Linear lin;
        lin.R = R;
        const FluxMap map(linear_flux_map(lin.L_d, lin.L_q, lin.psi_m, 1000.0, 21));
        const InverseFluxMap inv(map);
        CvodeSettings s;
        s.rtol = tol;
        s.atol = tol * 1e-2;
        s.init_step = CvodeInitStep::curvature;
        s.max_steps = 100000;
        for (double w_m : {0.0, 300.0, 1256.6}) {
            CvodeIntegrator integ(s);
            integ.reset(0.0, lin.psi_m, 0.0);
            DqFluxOde ode;
            ode.inverse = &inv;
            ode.omega = 4 * w_m;
            ode.R = lin.R;
            Eigen::Vector2d psi(lin.psi_m, 0.0);
            double err = 0, imax = 0;
            for (int k = 0; k < 80; ++k) {
                ode.u_d = (k < 30 ? -30.0 : 10.0) * (R > 1 ? 20 : 1);
                ode.u_q = (k < 30 ? 40.0 : -20.0) * (R > 1 ? 20 : 1) + 0.3 * ode.omega / 4;
                integ.advance(ode, h);
                psi = linear_step(lin, ode.omega, ode.u_d, ode.u_q, psi, h);
                const InverseFluxPoint c = inv.eval(integ.state().psi[0], integ.state().psi[1]);
                const double id = (psi(0) - lin.psi_m) / lin.L_d, iq = psi(1) / lin.L_q;
                err = std::max({err, std::abs(c.i_d - id), std::abs(c.i_q - iq)});
                imax = std::max({imax, std::abs(id), std::abs(iq)});
            }
            EXPECT_LT(err, 1e-6 * imax) << "R = " << R << ", w_m = " << w_m << ": max error " << err << " A of " << imax
                                        << " A";
            EXPECT_GT(imax, 50.0);  // the run is not trivial
        }
    }
}

TEST(PlantOde, PowerBalanceIdentity) {
    // P_elec = 1.5 i . dpsi/dt + P_cu + T_e w_m, and P_mech = T_e w_m - P_fe, at any state.
    const FluxMap map(read_flux_map(kDefaultMap));
    const InverseFluxMap inv(map);
    DqFluxOde ode{&inv, -80.0, 120.0, 4 * 600.0, 0.015, -0.003};
    const IronLossModel fe{1.06664735685, 2.0, 0.00581807649193, 0.0780669432093};
    for (auto [pd, pq] : {std::pair{0.05, 0.02}, {0.02, 0.1}, {-0.01, -0.05}}) {
        const double psi[2] = {pd, pq};
        double f[2];
        ode.rhs(psi, f);
        const PlantOutputs o = plant_outputs(ode, 4, 600.0, fe, pd, pq);
        const double dW = 1.5 * (o.i_d * f[0] + o.i_q * f[1]);
        EXPECT_NEAR(o.P_elec, dW + o.P_cu + o.T_e * 600.0, 1e-9 * std::abs(o.P_elec) + 1e-9);
        EXPECT_NEAR(o.P_mech, o.T_e * 600.0 - o.P_fe, 1e-9 * std::abs(o.P_mech) + 1e-9);
        EXPECT_GT(o.P_fe, 0.0);
    }
    const PlantOutputs still = plant_outputs(ode, 4, 0.0, fe, 0.05, 0.02);
    EXPECT_EQ(still.P_fe, 0.0);
    EXPECT_EQ(still.T_shaft, still.T_e);
}

class IntegratorFixture : public testing::Test {
protected:
    IntegratorFixture() : map_(read_flux_map(kDefaultMap)), inv_(map_) {
        ode_.inverse = &inv_;
        ode_.omega = 4 * 1256.6;
        ode_.R = 0.012;
    }
    void drive(CvodeIntegrator& integ, int from, int to) {
        for (int k = from; k < to; ++k) {
            ode_.u_d = (k / 7) % 2 == 0 ? -60.0 : -75.0;
            ode_.u_q = (k / 7) % 2 == 0 ? 395.0 : 380.0;
            integ.advance(ode_, 1e-4);
        }
    }
    FluxMap map_;
    InverseFluxMap inv_;
    DqFluxOde ode_;
};

TEST_F(IntegratorFixture, CopiesAndRestoredStatesAreBitIdentical) {
    CvodeIntegrator a;
    a.reset(0.0, map_.psi_m(), 0.0);
    drive(a, 0, 20);
    const CvodeState saved = a.state();
    CvodeIntegrator copy(a);  // no workspace: a fresh CVODE instance on its first advance()
    drive(a, 20, 60);
    drive(copy, 20, 60);
    EXPECT_TRUE(same_bits(a.state().psi[0], copy.state().psi[0]));
    EXPECT_TRUE(same_bits(a.state().psi[1], copy.state().psi[1]));
    EXPECT_GT(a.stats().steps, 0);

    // Roll a back (its workspace has seen the whole run) and repeat: the same bits.
    const CvodeState end = a.state();
    a.set_state(saved);
    drive(a, 20, 60);
    EXPECT_TRUE(same_bits(a.state().psi[0], end.psi[0]));
    EXPECT_TRUE(same_bits(a.state().psi[1], end.psi[1]));

    // Copy-assignment into an integrator with its own history, and moves.
    CvodeIntegrator other;
    other.reset(0.0, 0.01, 0.02);
    drive(other, 0, 5);
    other = copy;
    other.set_state(saved);
    drive(other, 20, 60);
    EXPECT_TRUE(same_bits(other.state().psi[0], end.psi[0]));
    CvodeIntegrator moved(std::move(other));
    moved.set_state(saved);
    drive(moved, 20, 60);
    EXPECT_TRUE(same_bits(moved.state().psi[1], end.psi[1]));
}

TEST_F(IntegratorFixture, FailureThrowsCvodeMessageAndKeepsState) {
    CvodeSettings s;
    s.max_steps = 1;
    s.rtol = s.atol = 1e-13;  // more than one step even for the small remainder CVODE integrates
    CvodeIntegrator integ(s);
    integ.reset(0.0, map_.psi_m(), 0.0);
    const CvodeState before = integ.state();
    ode_.u_d = 0;
    ode_.u_q = 150;
    try {
        integ.advance(ode_, 1e-4);
        FAIL() << "no exception";
    } catch (const CvodeError& e) {
        EXPECT_NE(std::string(e.what()).find("mxstep steps taken before reaching tout"), std::string::npos) << e.what();
        EXPECT_NE(std::string(e.what()).find("CV_TOO_MUCH_WORK"), std::string::npos) << e.what();
    }
    EXPECT_TRUE(same_bits(integ.state().psi[0], before.psi[0]));
    EXPECT_EQ(integ.state().t, before.t);
    s = CvodeSettings{};
    integ.set_settings(s);
    EXPECT_NO_THROW(integ.advance(ode_, 1e-4));
    EXPECT_EQ(integ.state().t, 1e-4);

    // A non-finite state: CVODE's RHS failure, not a crash.
    CvodeState bad = integ.state();
    bad.psi[0] = std::nan("");
    integ.set_state(bad);
    EXPECT_THROW(integ.advance(ode_, 1e-4), CvodeError);
}

TEST_F(IntegratorFixture, TinyIntervalsAndMethodsAgree) {
    CvodeIntegrator a;
    a.reset(1.0, map_.psi_m(), 0.0);
    ode_.u_d = -60;
    ode_.u_q = 395;
    EXPECT_NO_THROW(a.advance(ode_, std::nextafter(1.0, 2.0) - 1.0));  // a step of one ulp of t
    EXPECT_EQ(a.state().t, std::nextafter(1.0, 2.0));

    CvodeSettings bdf;
    bdf.method = CvodeMethod::bdf;
    bdf.nonlinear = CvodeNonlinear::newton_analytic;
    bdf.init_step = CvodeInitStep::curvature;
    for (CvodeSettings s : {CvodeSettings{}, bdf}) {
        s.rtol = s.atol = 1e-10;
        s.max_steps = 100000;
        CvodeIntegrator x(s);
        x.reset(0.0, map_.psi_m(), 0.0);
        drive(x, 0, 30);
        CvodeIntegrator ref;  // defaults (Adams, 1e-6)
        ref.reset(0.0, map_.psi_m(), 0.0);
        drive(ref, 0, 30);
        EXPECT_NEAR(x.state().psi[0], ref.state().psi[0], 2e-5);
        EXPECT_NEAR(x.state().psi[1], ref.state().psi[1], 2e-5);
    }
}

// At 12 000 r/min the frame turns by about half a radian per 100-us step, and the step integrals'
// integrands carry that rotation of the currents: where one explicit step over the whole call
// misses the tolerances, shorter explicit steps finish the call (CVODE, restarting at order 1,
// needed many steps and ten times the time there). The result must still be what a tight
// integration gives, fluxes and integrals alike.
TEST_F(IntegratorFixture, ExplicitStepsFinishCallsOneStepMissesAndAgreeWithATightIntegration) {
    const fmi::Context context = context_with();
    const PlantModel plant(context);  // its default iron loss
    const StepIntegrands q{4, 1256.6, plant.iron_loss};
    CvodeSettings fast;  // the plant's choice (PlantModel::settings)
    fast.init_step = CvodeInitStep::curvature;
    fast.nonlin_conv_coef = 0.3;
    fast.current_scale = 1000.0;
    CvodeSettings cvode_only = fast, tight = fast;
    fast.explicit_first = true;
    tight.rtol = tight.atol = 1e-11;
    tight.max_steps = 100000;
    CvodeIntegrator a(fast), cv(cvode_only), ref(tight);
    a.reset(0.0, map_.psi_m(), 0.0);
    int one_step = 0, several = 0, by_cvode = 0;
    // Each call's error against the tight integration from the same start (the tight one agrees
    // with CVODE on psi itself at that tolerance to 3e-8 of the call's energy): the largest over
    // the run, fluxes in Wb, integrals relative to the largest magnitude each reaches. CVODE alone
    // at the same tolerances for comparison; and the sums over the run.
    double err_psi = 0, err_psi_cv = 0, err_q[StepIntegrands::count] = {}, err_q_cv[StepIntegrands::count] = {},
           scale_q[StepIntegrands::count] = {}, sum_q[StepIntegrands::count] = {}, sum_ref[StepIntegrands::count] = {};
    for (int k = 0; k < 200; ++k) {
        ode_.u_d = (k / 7) % 2 == 0 ? -60.0 : -75.0;
        ode_.u_q = (k / 7) % 2 == 0 ? 395.0 : 380.0;
        const CvodeState start = a.state();
        a.advance(ode_, 1e-4, &q);
        ref.set_state(start);
        ref.advance(ode_, 1e-4, &q);
        cv.set_state(start);
        cv.advance(ode_, 1e-4, &q);
        (a.stats().explicit_only ? (a.stats().steps == 1 ? one_step : several) : by_cvode)++;
        for (int j = 0; j < 2; ++j) {
            err_psi = std::max(err_psi, std::abs(a.state().psi[j] - ref.state().psi[j]));
            err_psi_cv = std::max(err_psi_cv, std::abs(cv.state().psi[j] - ref.state().psi[j]));
        }
        for (int j = 0; j < StepIntegrands::count; ++j) {
            const double r = ref.step_integrals()[j];
            err_q[j] = std::max(err_q[j], std::abs(a.step_integrals()[j] - r));
            err_q_cv[j] = std::max(err_q_cv[j], std::abs(cv.step_integrals()[j] - r));
            scale_q[j] = std::max(scale_q[j], std::abs(r));
            sum_q[j] += a.step_integrals()[j];
            sum_ref[j] += r;
        }
    }
    std::printf(
        "calls: one explicit step %d, several %d, CVODE %d; largest error per call: psi %.2g Wb (CVODE alone "
        "%.2g)",
        one_step, several, by_cvode, err_psi, err_psi_cv);
    for (int j = 0; j < StepIntegrands::count; ++j)
        std::printf(", integral %d %.2g (%.2g), sum %.2g", j, err_q[j] / scale_q[j], err_q_cv[j] / scale_q[j],
                    std::abs(sum_q[j] - sum_ref[j]) / std::abs(sum_ref[j]));
    std::printf("\n");
    EXPECT_GT(several, 20);         // the case this is about happens here
    EXPECT_LE(by_cvode, 200 / 20);  // and CVODE is the exception
    // No less accurate than CVODE at the same tolerances.
    EXPECT_LE(err_psi, std::max(err_psi_cv, 1e-8));
    for (int j = 0; j < StepIntegrands::count; ++j) {
        EXPECT_LE(err_q[j], err_q_cv[j]) << "integral " << j;
        EXPECT_LT(std::abs(sum_q[j] - sum_ref[j]), 1e-4 * std::abs(sum_ref[j])) << "integral " << j;
    }
}

TEST(PlantModel, DefaultsAreTheDefaultMotor) {
    const FluxMapTable t = read_flux_map(kDefaultMap);
    const PlantModel m(context_with());
    EXPECT_EQ(m.motor.pole_pairs, t.metadata_number("pole_pairs", 0));
    EXPECT_DOUBLE_EQ(m.motor.R_s, t.metadata_number("R_s_ohm", 0));
    EXPECT_DOUBLE_EQ(m.motor.T_winding_ref, t.metadata_number("T_winding_ref_K", 0));
    EXPECT_DOUBLE_EQ(m.motor.alpha_cu, t.metadata_number("alpha_cu_per_K", 0));
    EXPECT_DOUBLE_EQ(m.motor.T_magnet_ref, t.metadata_number("T_magnet_ref_K", 0));
    EXPECT_DOUBLE_EQ(m.motor.k_psi_T, t.metadata_number("k_psi_T_per_K", 0));
    EXPECT_DOUBLE_EQ(m.iron_loss.k_h, t.metadata_number("fe_k_h_W_per_Hz", 0));
    EXPECT_DOUBLE_EQ(m.iron_loss.alpha, t.metadata_number("fe_alpha", 0));
    EXPECT_DOUBLE_EQ(m.iron_loss.k_e, t.metadata_number("fe_k_e_W_per_Hz2", 0));
    EXPECT_DOUBLE_EQ(m.iron_loss.psi_ref, t.metadata_number("fe_psi_ref_Wb", 0));
}

TEST(PlantModel, InitialOutputsAreConsistent) {
    std::vector<std::string> warnings;
    PlantModel m(context_with(&warnings));
    m.T_magnet = 373.15;
    m.T_winding = 393.15;
    m.exit_initialization();
    EXPECT_TRUE(warnings.empty()) << warnings.front();
    const double psi_m = 0.0780669432093;
    EXPECT_NEAR(m.psi_d, psi_m * (1 - 0.0012 * 80), 1e-12);
    EXPECT_NEAR(m.psi_m_T, m.psi_d, 1e-15);
    EXPECT_EQ(m.psi_q, 0.0);
    EXPECT_NEAR(m.i_d, 0.0, 1e-6);
    EXPECT_NEAR(m.i_q, 0.0, 1e-6);
    EXPECT_NEAR(m.T_e, 0.0, 1e-6);
    EXPECT_NEAR(m.R_s_T, 0.012 * (1 + 0.00393 * 100), 1e-15);
    EXPECT_EQ(m.P_fe, 0.0);

    PlantModel loaded(context_with());
    loaded.i_d_start = -200;
    loaded.i_q_start = 300;
    loaded.exit_initialization();
    EXPECT_NEAR(loaded.i_d, -200, 1e-4);
    EXPECT_NEAR(loaded.i_q, 300, 1e-4);
    EXPECT_GT(loaded.T_e, 100);
}

TEST(PlantModel, BadMapsAndParametersAreRefusedAndChangeNothing) {
    const FluxMapTable good = linear_flux_map(0.25e-3, 0.6e-3, 0.08, 500, 9);
    std::string csv = csv_of(good);
    const std::string malformed = temp_file("malformed.csv", std::string(csv).replace(csv.find("\n") + 1, 4, "abc,"));
    const std::string missing_row = temp_file("missing_row.csv", csv.substr(0, csv.rfind('\n', csv.size() - 2) + 1));
    FluxMapTable fold = good;
    fold.psi_d[40] = fold.psi_d[39] - 0.01;  // psi_d falls with i_d: not invertible
    const std::string not_monotone = temp_file("not_monotone.csv", csv_of(fold));
    const std::vector<std::pair<std::function<void(PlantModel&)>, std::string>> cases = {
        {[](PlantModel& m) { m.motor.flux_map = "/nonexistent/map.csv"; }, "/nonexistent/map.csv"},
        {[&](PlantModel& m) { m.motor.flux_map = malformed; }, "malformed.csv"},
        {[&](PlantModel& m) { m.motor.flux_map = missing_row; }, "missing_row.csv"},
        {[&](PlantModel& m) { m.motor.flux_map = not_monotone; }, "not_monotone.csv"},
        {[](PlantModel& m) {
             m.cvode_method = 2;
             m.cvode_max_order = 7;
         },
         "cvode_max_order"},
        {[](PlantModel& m) {
             m.motor.alpha_cu = 0.009;
             m.motor.T_winding_ref = 573.15;
         },
         "negative"},
    };
    for (const auto& [change, expected] : cases) {
        PlantModel m(context_with());
        change(m);
        try {
            m.exit_initialization();
            ADD_FAILURE() << "accepted: " << expected;
        } catch (const fmi::Error& e) {
            EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
        }
        // Unchanged: still not initialised.
        EXPECT_THROW(m.do_step(0.0, 1e-4), fmi::Error);
    }
    fmi::Context no_resources = context_with();
    no_resources.resource_dir.clear();
    PlantModel m(no_resources);
    EXPECT_THROW(m.exit_initialization(), fmi::Error);
}

TEST(PlantModel, StepFailureLeavesTheModelUnchanged) {
    PlantModel m(context_with());
    m.exit_initialization();
    inputs(m, 0, 1256.6);
    m.do_step(0.0, 1e-4);
    const std::vector<double> before = outputs(m);
    m.cvode_max_steps = 1;
    m.rtol = 1e-14;  // more than one step even for the small remainder CVODE integrates
    m.atol = 1e-15;
    m.u_q = 500.0;
    try {
        m.do_step(1e-4, 1e-4);
        FAIL();
    } catch (const fmi::Error& e) {
        EXPECT_NE(std::string(e.what()).find("mxstep"), std::string::npos) << e.what();
    }
    EXPECT_EQ(outputs(m), before);
    m.cvode_max_steps = 20000;
    m.rtol = m.atol = 1e-6;
    EXPECT_NO_THROW(m.do_step(1e-4, 1e-4));
}

TEST(PlantModel, CopySaveAndLoadAreExact) {
    PlantModel m(context_with());
    m.exit_initialization();
    for (int k = 0; k < 40; ++k) {
        inputs(m, k, 900.0);
        m.do_step(k * 1e-4, 1e-4);
    }
    PlantModel copy(m);
    const std::vector<char> bytes = fmi::save_state_fields(m);
    PlantModel restored(context_with());  // a fresh instance, as fmi2DeSerializeFMUstate makes
    restored.exit_initialization();
    fmi::load_state_fields(restored, bytes.data(), bytes.size());
    for (int k = 40; k < 100; ++k) {
        for (PlantModel* x : {&m, &copy, &restored}) {
            inputs(*x, k, 900.0);
            x->do_step(k * 1e-4, 1e-4);
        }
        const auto a = outputs(m), b = outputs(copy), c = outputs(restored);
        for (std::size_t j = 0; j < a.size(); ++j) {
            ASSERT_TRUE(same_bits(a[j], b[j])) << "copy, step " << k << ", output " << j;
            ASSERT_TRUE(same_bits(a[j], c[j])) << "restored, step " << k << ", output " << j;
        }
    }
}

// --- the inverter's safe states (plant/inverter_state.hpp, freewheel_integrator.hpp) -----------

// On an isotropic machine (L0 = l I) the bridge's directions are +-e0/|e0| with
// lambda = (+-|e0| - k) / l: the onset direction +e0 above the onset, two decaying ones below.
TEST(BridgeDirections, IsotropicMachineClosedForm) {
    const double l = 2e-4, L0[4] = {l, 0, 0, l}, k = 226.0;
    for (double e : {100.0, 200.0, 250.0, 400.0}) {
        const double e0[2] = {0.3 * e, -std::sqrt(1 - 0.09) * e};
        const BridgeDirections d = bridge_directions(e0, k, L0);
        EXPECT_EQ(d.has_onset, e > k) << e;
        if (e > k) {
            EXPECT_NEAR(d.onset[0], e0[0] / e, 1e-12);
            EXPECT_NEAR(d.onset[1], e0[1] / e, 1e-12);
            ASSERT_EQ(d.n_decay, 1);  // against the back-EMF
            EXPECT_NEAR(d.decay[0][0], -e0[0] / e, 1e-12);
        } else {
            ASSERT_EQ(d.n_decay, 2);  // with and against the back-EMF
            const double dot = d.decay[0][0] * d.decay[1][0] + d.decay[0][1] * d.decay[1][1];
            EXPECT_NEAR(dot, -1.0, 1e-12);
        }
    }
}

// Each direction solves e0 = (k I + lambda L0) n on an anisotropic, cross-coupled L0.
TEST(BridgeDirections, SolveTheirEquation) {
    const double L0[4] = {1.2e-4, 0.1e-4, 0.1e-4, 4.0e-4}, k = 226.0;
    for (double e : {150.0, 300.0}) {
        const double e0[2] = {0.2 * e, -std::sqrt(0.96) * e};
        const BridgeDirections d = bridge_directions(e0, k, L0);
        std::vector<std::array<double, 2>> all;
        for (int j = 0; j < d.n_decay; ++j) all.push_back({d.decay[j][0], d.decay[j][1]});
        if (d.has_onset) all.push_back({d.onset[0], d.onset[1]});
        ASSERT_GE(all.size(), 2u);
        for (const auto& n : all) {
            const double l[2] = {L0[0] * n[0] + L0[1] * n[1], L0[2] * n[0] + L0[3] * n[1]};
            const double r[2] = {e0[0] - k * n[0], e0[1] - k * n[1]};
            EXPECT_NEAR(l[0] * r[1] - l[1] * r[0], 0.0, 1e-10 * e * 4e-4);  // (e0 - k n) parallel to L0 n
            EXPECT_NEAR(std::hypot(n[0], n[1]), 1.0, 1e-14);
        }
    }
}

// Blocked below the onset, a freewheeling step is exact: i = 0, psi = psi_0, only the iron loss.
TEST(FreewheelIntegrator, BlockedStepIsExact) {
    const FluxMap map(linear_flux_map(0.25e-3, 0.6e-3, 0.08, 1000.0, 21));
    const InverseFluxMap inverse(map);
    DqFluxOde o;
    o.inverse = &inverse;
    o.omega = 2000.0;  // |e0| = 160 V < k
    o.R = 0.05;
    StepIntegrands q{4, 500.0, IronLossModel{1.0, 2.0, 0.005, 0.08}};
    CvodeSettings s;
    FreewheelIntegrator fw;
    const double psi0[2] = {0.08, 0.0}, seed[2] = {0.0, 0.0};
    const FreewheelStep r = fw.advance(o, 226.0, q, s, 1e-4, psi0, true, seed, 0.0);
    EXPECT_TRUE(r.blocked);
    EXPECT_EQ(r.switchings, 0);
    EXPECT_EQ(r.integrals[StepIntegrands::P_elec], 0.0);
    EXPECT_EQ(r.integrals[StepIntegrands::P_cu], 0.0);
    EXPECT_EQ(r.integrals[StepIntegrands::T_e], 0.0);
    EXPECT_DOUBLE_EQ(r.integrals[StepIntegrands::P_fe], 1e-4 * q.fe.power(4, 500.0, 0.08, 0.0));
}
