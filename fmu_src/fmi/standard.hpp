// The FMI standards the glue speaks (FMI 2.0, FMI 3.0): what its messages call the functions the
// two share, and the salt of an instance's tag. The functions themselves are in
// glue_functions.hpp (shared), fmi2_functions.hpp and fmi3_functions.hpp (each standard's own).
// Nothing here depends on a model or on the FMI C headers.
#pragma once

#include <cstdint>

namespace fmi {

// The value reference of FMI 3.0's independent variable `time`: fixed, far beyond the table's
// positions (the other value references), so that a variable added to a table never moves it.
inline constexpr std::uint32_t kTimeValueReference = 2147483647;  // 2^31 - 1

struct Standard {
    const char* version;  // "2.0", "3.0"
    int major;            // 2, 3
    std::uint64_t salt;   // xor-ed into an instance's tag: an FMI 2.0 instance is not an FMI 3.0 one
    bool time_variable;   // the independent variable `time` (FMI 3.0), value reference kTimeValueReference
    const char* error;    // the status a refused call returns
    const char* free_instance;
    const char* set_debug_logging;
    const char* enter_initialization_mode;
    const char* exit_initialization_mode;
    const char* terminate;
    const char* reset;
    const char* get_fmu_state;
    const char* set_fmu_state;
    const char* free_fmu_state;
    const char* serialized_fmu_state_size;
    const char* serialize_fmu_state;
    const char* deserialize_fmu_state;
    const char* do_step;
    const char* set_real;  // the Set function of Reals (Float64)
};

inline constexpr Standard fmi2_standard{
    "2.0",
    2,
    0,
    false,
    "fmi2Error",
    "fmi2FreeInstance",
    "fmi2SetDebugLogging",
    "fmi2EnterInitializationMode",
    "fmi2ExitInitializationMode",
    "fmi2Terminate",
    "fmi2Reset",
    "fmi2GetFMUstate",
    "fmi2SetFMUstate",
    "fmi2FreeFMUstate",
    "fmi2SerializedFMUstateSize",
    "fmi2SerializeFMUstate",
    "fmi2DeSerializeFMUstate",
    "fmi2DoStep",
    "fmi2SetReal",
};

inline constexpr Standard fmi3_standard{
    "3.0",
    3,
    0x464d4933ull,  // "FMI3"
    true,
    "fmi3Error",
    "fmi3FreeInstance",
    "fmi3SetDebugLogging",
    "fmi3EnterInitializationMode",
    "fmi3ExitInitializationMode",
    "fmi3Terminate",
    "fmi3Reset",
    "fmi3GetFMUState",
    "fmi3SetFMUState",
    "fmi3FreeFMUState",
    "fmi3SerializedFMUStateSize",
    "fmi3SerializeFMUState",
    "fmi3DeserializeFMUState",
    "fmi3DoStep",
    "fmi3SetFloat64",
};

}  // namespace fmi
