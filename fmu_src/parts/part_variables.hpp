// The FMI variables of the parameter structs ("parts") the models hold: the motor, its iron loss,
// the inverter and the thermal network. Each parameter's name, unit, range and description is
// declared here once; a model places a part's variables in its own table by name
// (fmi::part_variable, where their value references are to be) or whole (fmi::part_variables),
// and IpmsmDrive forwards them to every model that holds them. The structs themselves are the
// physics' (machine/, inverter/, thermal/), free of FMI.
//
// A new parameter of a part: its member in the struct and its line in the part's table here;
// each model that holds the part then takes it at the end of its table (value references only
// grow; tests/cpp/test_parts.cpp fails while one lacks it), and IpmsmDrive forwards it by itself.
#pragma once

#include <vector>

#include "inverter/inverter_loss.hpp"
#include "machine/iron_loss.hpp"
#include "machine/motor_params.hpp"
#include "thermal/motor_lptn.hpp"
#include "variable.hpp"

namespace ipmsm {

const std::vector<fmi::Variable<MotorParams>>& variables_of(const MotorParams*);
const std::vector<fmi::Variable<IronLossModel>>& variables_of(const IronLossModel*);
const std::vector<fmi::Variable<InverterParams>>& variables_of(const InverterParams*);

namespace thermal {
const std::vector<fmi::Variable<LptnParams>>& variables_of(const LptnParams*);
}  // namespace thermal

}  // namespace ipmsm
