// Current-minimising commands on a saturated machine, given by its flux map.
//   recursion 0: Ferrari with the nominal (unsaturated, small-signal) inductances at i = 0.
//   recursion 1: the paper's recursion: apparent inductances L_d = (psi_d(i) - psi_d(0, i_q)) / i_d,
//                L_q = psi_q(i) / i_q and psi_m = psi_d(0, i_q) at the last solution, Ferrari
//                again, until the command moves by less than 0.05 A. Meets the torque exactly,
//                but its MTPA ignores dL/di and so uses more current than needed.
//   recursion 2: the true optimum on the map: Newton on the exact optimality conditions
//                (map_newton.hpp), seeded by one Ferrari solve with apparent inductances.
//                T_max and the case by the same decisions as the linear machine (decision.hpp),
//                each condition solved by Newton on the map.
// Recursion 2 depends on its inputs only; recursion 1 starts from its last solutions (a drive's
// commands move little between 100-us samples), a memory that is part of the FMU state.
#pragma once

#include <cmath>
#include <memory>

#include "control/current_circles.hpp"
#include "control/linear_optimal_current.hpp"
#include "machine/flux_map.hpp"
#include "machine/machine.hpp"
#include "machine/magnet_flux.hpp"

namespace ipmsm {

enum class Recursion : int { nominal = 0, apparent = 1, optimal = 2 };

// The torque along the current circles (CurrentCircles): per torque side and circle, MTPA at that
// current polished on the map from the circle's best sample (its global maximum along the
// circle). Found for a magnet shift rounded to kShiftStep: they only seed Newton at the exact
// shift, so a drifting magnet temperature does not find them again every call, and the answer
// stays a function of the inputs.
struct CircleMaxima {
    static constexpr double kShiftStep = 1e-4;  // Wb: 0.1 % of a typical psi_m
    // MTPV seeds: for flux levels |psi| = psi_level[l] (the lossless voltage limit V_max / |omega|),
    // the sampled point of most torque where a circle crosses that level (within the current
    // circle, then: on it where the torque still rises along the level at I_max).
    static constexpr int kFluxLevels = 48;
    struct Side {
        double T[CurrentCircles::kRadii + 1];  // s T' at MTPA on circle k (k = 0: the origin)
        CurrentPoint mtpa[CurrentCircles::kRadii + 1];
        bool converged[CurrentCircles::kRadii + 1];  // Newton converged to at least the best sample's torque
        CurrentPoint mtpv[kFluxLevels];
        bool has_mtpv[kFluxLevels];
        bool mtpv_on_current_limit[kFluxLevels];  // that sample lies on the circle |i| = I_max
    };
    double psi_min = 0, psi_max = 0;  // the levels, evenly spaced
    double psi_level(int l) const { return psi_min + (psi_max - psi_min) * l / (kFluxLevels - 1); }
    double shift = NAN;  // rounded
    Side sides[2];       // T > 0, T < 0
    const Side& side(double s) const { return sides[s < 0 ? 1 : 0]; }
};

// What the check of a command found (docs/controller.md, "Commands checked before they leave"):
// every command is verified on the map before it leaves; where the check fails, the robust search
// (level_search.hpp) or, for the approximate methods, the exact solver's command takes over.
enum class CheckFinding : int {
    passed = 0,
    torque,             // its torque on the map is not T_cmd
    current_limit,      // |i| above I_max
    voltage_limit,      // |v| above V_max
    not_least_current,  // a point of less current makes the torque within the limits
    torque_max,         // its T_max is not the map's (the robust search found more torque within the limits)
    branch,             // i_d > 0 on a magnet-free machine (the tie convention: i_d <= 0)
    not_finite,
    not_least_loss,     // objective 1: a point of the shaft-torque curve within the limits loses less
};
const char* describe(CheckFinding f);

struct CheckRecord {
    CheckFinding finding = CheckFinding::passed;
    CurrentCommand rejected;    // the command that failed (finding != passed)
    double T_target = 0;        // N.m, the torque it should have made (signed)
    double T_made = 0;          // N.m, what it makes on the map
    bool replaced = false;      // a command that passes took its place
    bool searched_max = false;  // T_max's point was not shown a local maximum: the robust search ran
};

// The paper's recursion (recursion 1) starts from its last solutions.
struct SolverMemory {
    double op_i_d = 0, op_i_q = 0;        // last command
    double limit_i_d = 0, limit_i_q = 0;  // last T_max point
    bool has_limit = false;

    // field(x) for every member, in a fixed order (a model's state, fmi/model.hpp).
    template <class Field>
    void fields(Field&& field) {
        field(op_i_d), field(op_i_q), field(limit_i_d), field(limit_i_q), field(has_limit);
    }
};

// Every method commands currents in the half disk |i| <= I_max, i_d <= 0, and the map must cover it:
// beyond its grid the map is an extrapolation, not the machine. Throws std::invalid_argument naming
// I_max and the grid's reach if it does not.
void check_current_limit_within_map(const FluxMap& map, double I_max);

class SaturatedOptimalCurrent {
public:
    SaturatedOptimalCurrent(std::shared_ptr<const FluxMap> map, int pole_pairs);

    // psi_d_shift: magnet-temperature shift of psi_d (magnet_flux_shift()). Recursion 2's
    // commands are checked (and replaced where the check fails) before they are returned;
    // last_check says what the check found.
    CurrentCommand solve(double T_ref, const OperatingLimits& lim, double R_s, double psi_d_shift, Recursion mode);

    // The check of another method's command (recursions 0 and 1, the 2-D tables): against the
    // exact solver's checked command for the same inputs. Returns `cmd` where it is that command
    // to the check's tolerances (torque within kTorqueTolerance of T_max, limits, current within
    // kCurrentTolerance of the least), else the exact one (last_check says why).
    CurrentCommand checked(const CurrentCommand& cmd, double T_ref, const OperatingLimits& lim, double R_s,
                           double psi_d_shift);
    CheckRecord last_check;

    // Tolerances of the check: torque relative to T_max, current relative to the least current
    // (with an absolute floor of kSmallCurrent I_max), limits relative.
    static constexpr double kTorqueTolerance = 1e-7;
    static constexpr double kCurrentTolerance = 1e-5;
    static constexpr double kSmallCurrent = 1e-9;
    static constexpr double kLimitTolerance = 1e-9;

    // The linear model a recursion step would use at (i_d, i_q).
    LinearMachine apparent_machine(const MagnetFlux& flux, double i_d, double i_q, double R_s) const;
    LinearMachine nominal_machine(double R_s, double psi_d_shift) const;

    const FluxMap& map() const { return *map_; }
    int pole_pairs() const { return pole_pairs_; }
    // No magnet (psi_d(0, 0) a negligible fraction of the map's flux): its optima come in mirror
    // pairs i, -i (psi(-i) = -psi(i)), and every method keeps to the branch i_d <= 0.
    bool magnet_free() const { return magnet_free_; }
    double resolution() const { return resolution_; }  // the map's smallest grid spacing, A
    // |psi_d(0, 0)| below this fraction of the largest |psi| on the grid is no magnet (PM machines
    // have tens of per cent, PM-assisted synchronous-reluctance machines several per cent).
    static constexpr double kMagnetFreeFluxRatio = 1e-3;
    SolverMemory memory;

    // Convergence threshold of the paper's recursion (seed: 0.05 A).
    static constexpr double recursion_tolerance_A = 0.05;
    static constexpr int recursion_max_iterations = 30;

private:
    CurrentCommand solve_recursive(double T_ref, const OperatingLimits& lim, double R_s, const MagnetFlux& flux);
    CurrentCommand solve_optimal(double T_ref, const OperatingLimits& lim, double R_s, const MagnetFlux& flux);
    // The check of recursion 2's command (cheap: the map at the command and at one circle's MTPA
    // point); where it fails, the robust search's command. last_check also holds T_max's finding
    // (solve_optimal checks T_max before the command is made from it).
    CurrentCommand check_optimal(CurrentCommand cmd, double T_ref, const OperatingLimits& lim, double R_s,
                                 const MagnetFlux& flux);
    CurrentCommand check_command(CurrentCommand cmd, double T_ref, const OperatingLimits& lim, double R_s,
                                 const MagnetFlux& flux);
    static Region limit_region(const MagnetFlux& flux, const OperatingLimits& lim, double R_s, CurrentPoint p);
    CheckRecord top_check_;  // T_max's check in the last solve_optimal()

    // The circles and their maxima for the last I_max and magnet shift (recursion 2): computed
    // again when either changes, so the answer depends on the inputs only.
    const CircleMaxima& circle_maxima(const MagnetFlux& flux, double I_max);
    // Shared, not copied: the samples (128 kB) never change once made, and the FMI glue copies
    // the whole model at every step to undo a failed one.
    std::shared_ptr<const CurrentCircles> circles_;
    CircleMaxima maxima_;

    std::shared_ptr<const FluxMap> map_;
    int pole_pairs_;
    double nominal_L_d_, nominal_L_q_;  // incremental inductances at i = 0
    linear::CommandSolver linear_;      // Ferrari on a linear machine (recursions 0 and 1)
    double resolution_;                 // the map's smallest grid spacing, A (level_search.hpp)
    bool magnet_free_;
};

}  // namespace ipmsm
