// The decisions of MATH.md, written once for every machine model: which limit gives T_max at a
// speed ("Maximum torque at a speed") and which case gives the command ("Which case applies").
//
// A View answers each condition for one machine model and one operating point, all on the
// T' >= 0 side (the caller mirrors T < 0): the linear machine in closed form
// (linear_optimal_current.cpp), or the flux map by Newton seeded by the linear closed forms
// (saturated_optimal_current.cpp). Each condition returns false if it has no point (or, on the
// map, did not converge). The View's interface:
//   bool mtpa_at_current_limit(CurrentPoint&)       MTPA at I_max
//   bool mtpv(CurrentPoint&)                        the most torque on the voltage limit
//   bool current_voltage_intersection(CurrentPoint&) the current circle meets the voltage limit
//   bool mtpa(double T_red, CurrentPoint&)          Case i: the least current for T'
//   bool voltage_limit(double T_red, CurrentPoint&) Case ii: T' on the voltage limit, least current
//   bool zero_torque(CurrentPoint&)                 T' = 0 with the least current within V_max
//   bool within_voltage(CurrentPoint), within_current(CurrentPoint)
//   double torque(CurrentPoint)                     T' (>= 0 on this side)
#pragma once

#include "machine/machine.hpp"

namespace ipmsm::decision {

struct Choice {
    CurrentPoint point{0.0, 0.0};
    Region region = Region::zero_torque;
    bool feasible = true;  // false: no current within I_max brings the voltage within V_max
};

// MATH.md "Maximum torque at a speed": the first that applies. On the map its answer is checked
// before a command is made from it (saturated_optimal_current.cpp: a point that is not a local
// maximum within the limits hands over to max_torque_search.hpp, docs/controller.md).
template <class View>
Choice max_torque(View& v) {
    CurrentPoint p{0.0, 0.0};
    if (v.mtpa_at_current_limit(p) && v.within_voltage(p)) return {p, Region::mtpa, true};
    if (v.mtpv(p) && v.within_current(p)) return {p, Region::mtpv, true};
    if (v.current_voltage_intersection(p)) return {p, Region::current_and_voltage_limit, true};
    return {p, Region::zero_torque, false};  // above the maximum speed
}

// MATH.md "Which case applies", for 0 < T' < T_max: Case i if its voltage is within V_max, else
// Case ii. Returns false if neither has a point (the edge of reach).
template <class View>
bool command_case(View& v, double T_red, Choice& out) {
    CurrentPoint p{0.0, 0.0};
    if (v.mtpa(T_red, p) && v.within_voltage(p)) {
        out = {p, Region::mtpa, true};
        return true;
    }
    if (!v.voltage_limit(T_red, p)) return false;
    out = {p, Region::voltage_limit, true};
    return true;
}

// The command for T' >= 0 given T_max's point `top` (from max_torque): clamped to T_max, zero
// torque, or the case above. At the edge of reach (no point of either case) the limit point.
template <class View>
Choice command(View& v, double T_red, const Choice& top) {
    if (!top.feasible || T_red >= v.torque(top.point)) return top;
    Choice c;
    if (T_red == 0.0) {
        c.region = Region::zero_torque;
        if (!v.zero_torque(c.point)) c.point = top.point;
        return c;
    }
    return command_case(v, T_red, c) ? c : top;
}

}  // namespace ipmsm::decision
