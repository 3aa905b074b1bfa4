// The IpmsmPlant FMU's exported FMI 2.0 functions (or, with IPMSM_FMI2_GENERATOR, the generator
// of its modelDescription.xml): the shared glue instantiated for PlantModel.
#include "fmi2_glue.hpp"
#include "plant_model.hpp"

IPMSM_FMI2_EXPORT(ipmsm::PlantModel)
