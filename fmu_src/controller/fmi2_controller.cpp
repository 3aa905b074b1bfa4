// The IpmsmController FMU's exported FMI 2.0 functions (or, with IPMSM_FMI2_GENERATOR, the
// generator of its modelDescription.xml): the shared glue for ControllerModel.
#include "controller/controller_model.hpp"

using ExportedModel = ipmsm::ControllerModel;
#include "fmi2_entry_points.inc"
