// The IpmsmDrive FMU's exported FMI 2.0 functions (or, with IPMSM_FMI2_GENERATOR, the generator
// of its modelDescription.xml): the shared glue for DriveModel.
#include "drive/drive_model.hpp"

using ExportedModel = ipmsm::DriveModel;
#include "fmi2_entry_points.inc"
