// A fault-injection switch for the command check's tests: compiled in only where
// IPMSM_FAULT_INJECTION is defined, which only a test-only build of the control library does
// (tests/CMakeLists.txt, ipmsm_control_fault_injection); the shipped FMUs never define it, and
// there apply() is empty.
#pragma once

#include "machine/machine.hpp"

namespace ipmsm::fault_injection {

#ifdef IPMSM_FAULT_INJECTION
// Recursion 2's commands, before their check, have their current vector scaled by this factor
// (1: no fault).
inline double& current_scale() {
    static double scale = 1.0;
    return scale;
}
inline void apply(CurrentCommand& c) {
    c.i_d *= current_scale();
    c.i_q *= current_scale();
}
// T_max's point, before its check, has its current vector scaled by this factor (1: no fault).
inline double& top_scale() {
    static double scale = 1.0;
    return scale;
}
inline void apply_top(CurrentPoint& p) {
    p.i_d *= top_scale();
    p.i_q *= top_scale();
}
#else
inline void apply(CurrentCommand&) {}
inline void apply_top(CurrentPoint&) {}
#endif

}  // namespace ipmsm::fault_injection
