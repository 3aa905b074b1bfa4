// The IpmsmController FMU's exported FMI 3.0 functions (or, with IPMSM_FMI3_GENERATOR, the
// generator of its FMI 3.0 modelDescription.xml): the shared glue for ControllerModel.
#include "controller/controller_model.hpp"

using ExportedModel = ipmsm::ControllerModel;
#include "fmi3_entry_points.inc"
