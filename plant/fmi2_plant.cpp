// The IpmsmPlant FMU's exported FMI 2.0 functions (or, with IPMSM_FMI2_GENERATOR, the generator
// of its modelDescription.xml): the shared glue for PlantModel.
#include "plant_model.hpp"

using ExportedModel = ipmsm::PlantModel;
#include "fmi2_entry_points.inc"
