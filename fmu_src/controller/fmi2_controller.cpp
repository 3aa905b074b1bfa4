// The IpmsmController FMU's exported FMI 2.0 functions (or, with IPMSM_FMI2_GENERATOR, the
// generator of its modelDescription.xml): the shared glue instantiated for ControllerModel.
#include "controller_model.hpp"
#include "fmi2_glue.hpp"

IPMSM_FMI2_EXPORT(ipmsm::ControllerModel)
