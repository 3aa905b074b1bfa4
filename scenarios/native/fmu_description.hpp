// The C++ drivers of libipmsm_cosim (cosim_check, cosim_profile): both units started and coupled.
// The model descriptions are read by fmu_binary.hpp.
#pragma once

#include "cosim.h"
#include "fmu_binary.hpp"

namespace cosim_tools {

using fmu_binary::Description;
using fmu_binary::read_description;

// The inputs both units start from (a flying start at speed w_m).
struct Start {
    double T_ref, w_m, u_dc, T_magnet, T_winding;  // N.m, rad/s, V, K, K
};

// Both units initialised for a flying start and coupled (cosim.h; controller unit 0, plant unit
// 1). The plant first: the controller starts from the plant's initial current.
// plant_parameters(m) sets anything else of the plant in its Initialization Mode and returns a
// status. Stops at the first failing call and returns its status (ipmsm_cosim_error says why);
// 0 once coupled.
template <class PlantParameters>
int start_coupled(ipmsm_cosim* m, const Description& cd, const Description& pd, const Start& s,
                  PlantParameters&& plant_parameters) {
    const unsigned p_start_vr[3] = {pd.vr.at("w_m"), pd.vr.at("T_magnet"), pd.vr.at("T_winding")};
    const double p_start[3] = {s.w_m, s.T_magnet, s.T_winding};
    const unsigned p_i_vr[2] = {pd.vr.at("i_d"), pd.vr.at("i_q")};
    const unsigned c_start_vr[6] = {cd.vr.at("T_ref"), cd.vr.at("w_m"), cd.vr.at("u_dc"), cd.vr.at("T_magnet"),
                                    cd.vr.at("i_d"), cd.vr.at("i_q")};
    double c_start[6] = {s.T_ref, s.w_m, s.u_dc, s.T_magnet, 0.0, 0.0};  // + the plant's i_d, i_q
    const unsigned cvr[8] = {cd.vr.at("T_ref"), cd.vr.at("w_m"), cd.vr.at("u_dc"), cd.vr.at("T_magnet"),
                             cd.vr.at("i_d"), cd.vr.at("i_q"), cd.vr.at("u_d_ref"), cd.vr.at("u_q_ref")};
    const unsigned pvr[7] = {pd.vr.at("u_d"), pd.vr.at("u_q"), pd.vr.at("w_m"), pd.vr.at("T_magnet"),
                             pd.vr.at("T_winding"), pd.vr.at("i_d"), pd.vr.at("i_q")};
    int rc = ipmsm_cosim_enter_initialization(m, 1, 0.0);
    if (rc == 0) rc = plant_parameters(m);
    if (rc == 0) rc = ipmsm_cosim_set_real(m, 1, 3, p_start_vr, p_start);
    if (rc == 0) rc = ipmsm_cosim_exit_initialization(m, 1);
    if (rc == 0) rc = ipmsm_cosim_get_real(m, 1, 2, p_i_vr, c_start + 4);
    if (rc == 0) rc = ipmsm_cosim_enter_initialization(m, 0, 0.0);
    if (rc == 0) rc = ipmsm_cosim_set_real(m, 0, 6, c_start_vr, c_start);
    if (rc == 0) rc = ipmsm_cosim_exit_initialization(m, 0);
    if (rc == 0) rc = ipmsm_cosim_couple(m, cvr, pvr, 0);
    return rc;
}

inline int start_coupled(ipmsm_cosim* m, const Description& cd, const Description& pd, const Start& s) {
    return start_coupled(m, cd, pd, s, [](ipmsm_cosim*) { return 0; });
}

}  // namespace cosim_tools
