// CHECK(cond) for the C++ programs that drive FMUs without a test framework
// (plant_fmu_harness; run under valgrind): a failed check is reported with its line and counted,
// and the run goes on, so that one run reports every failure.
#pragma once

#include <cstdio>

namespace check {
inline int failures = 0;
}  // namespace check

#define CHECK(cond)                                                                 \
    do {                                                                            \
        if (!(cond)) {                                                              \
            std::fprintf(stderr, "CHECK failed at line %d: %s\n", __LINE__, #cond); \
            ++check::failures;                                                      \
        }                                                                           \
    } while (0)
