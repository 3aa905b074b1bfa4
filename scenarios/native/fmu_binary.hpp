// Importing an unzipped FMU in C++: the GUID and value references of its modelDescription.xml
// (read with a plain attribute search, enough for the files this project generates), and its
// binary's FMI 2.0 co-simulation functions, dlopened. Written once for every C++ importer in the
// repository: the native master (cosim.cpp) and its drivers, the plant benchmark
// (bench/bench_plant.cpp), the plant's valgrind harness and the C-API fuzzer (tests/cpp).
#pragma once

#include <dlfcn.h>

#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <sstream>
#include <string>

#include "fmi2Functions.h"

namespace fmu_binary {

// The value of attribute `attr` at or after `from` in `xml` ("" if there is none).
inline std::string attribute_after(const std::string& xml, std::size_t from, const char* attr) {
    const std::string key = std::string(" ") + attr + "=\"";
    const std::size_t a = xml.find(key, from);
    if (a == std::string::npos) return "";
    const std::size_t b = xml.find('"', a + key.size());
    return xml.substr(a + key.size(), b - a - key.size());
}

// What a master needs of a model description: the GUID and each variable's value reference.
struct Description {
    std::string guid;
    std::map<std::string, fmi2ValueReference> vr;
};

// <dir>/modelDescription.xml; exits with status 2 and a message if it cannot be read.
inline Description read_description(const std::string& dir) {
    std::ifstream f(dir + "/modelDescription.xml");
    std::stringstream ss;
    ss << f.rdbuf();
    const std::string xml = ss.str();
    Description d;
    d.guid = attribute_after(xml, 0, "guid");
    for (std::size_t p = xml.find("<ScalarVariable"); p != std::string::npos; p = xml.find("<ScalarVariable", p + 1))
        d.vr[attribute_after(xml, p, "name")] =
            static_cast<fmi2ValueReference>(std::stoul(attribute_after(xml, p, "valueReference")));
    if (d.guid.empty() || d.vr.empty()) {
        std::fprintf(stderr, "cannot read %s/modelDescription.xml\n", dir.c_str());
        std::exit(2);
    }
    return d;
}

// The binary of an unzipped FMU for this platform.
inline std::string library_path(const std::string& dir, const std::string& model_identifier) {
    return dir + "/binaries/linux64/" + model_identifier + ".so";
}

// Every FMI 2.0 function a co-simulation FMU exports, each named as in the standard.
#define FMU_BINARY_FUNCTIONS(X)                                                                                   \
    X(fmi2GetTypesPlatform) X(fmi2GetVersion) X(fmi2SetDebugLogging) X(fmi2Instantiate) X(fmi2FreeInstance)       \
    X(fmi2SetupExperiment) X(fmi2EnterInitializationMode) X(fmi2ExitInitializationMode) X(fmi2Terminate)         \
    X(fmi2Reset) X(fmi2GetReal) X(fmi2GetInteger) X(fmi2GetBoolean) X(fmi2GetString) X(fmi2SetReal)              \
    X(fmi2SetInteger) X(fmi2SetBoolean) X(fmi2SetString) X(fmi2GetFMUstate) X(fmi2SetFMUstate)                   \
    X(fmi2FreeFMUstate) X(fmi2SerializedFMUstateSize) X(fmi2SerializeFMUstate) X(fmi2DeSerializeFMUstate)        \
    X(fmi2GetDirectionalDerivative) X(fmi2SetRealInputDerivatives) X(fmi2GetRealOutputDerivatives) X(fmi2DoStep) \
    X(fmi2CancelStep) X(fmi2GetStatus) X(fmi2GetRealStatus) X(fmi2GetIntegerStatus) X(fmi2GetBooleanStatus)      \
    X(fmi2GetStringStatus)

// An FMU's binary, dlopened (RTLD_LOCAL: two FMUs' identical symbol names do not clash), with
// all its functions; closed when destroyed. Not copyable.
class Functions {
public:
#define FMU_BINARY_POINTER(name) name##TYPE* name = nullptr;
    FMU_BINARY_FUNCTIONS(FMU_BINARY_POINTER)
#undef FMU_BINARY_POINTER

    Functions() = default;
    Functions(const Functions&) = delete;
    Functions& operator=(const Functions&) = delete;
    ~Functions() { close(); }

    // Opens `library` and resolves every function. false, with why, if either fails (then closed).
    bool open(const std::string& library, std::string& why) {
        close();
        so_ = dlopen(library.c_str(), RTLD_NOW | RTLD_LOCAL);
        if (so_ == nullptr) {
            const char* e = dlerror();
            why = "cannot load " + library + ": " + (e != nullptr ? e : "dlopen failed");
            return false;
        }
#define FMU_BINARY_RESOLVE(name)                                          \
    name = reinterpret_cast<name##TYPE*>(dlsym(so_, #name));              \
    if (name == nullptr) {                                                \
        why = library + " does not export " #name;                        \
        close();                                                          \
        return false;                                                     \
    }
        FMU_BINARY_FUNCTIONS(FMU_BINARY_RESOLVE)
#undef FMU_BINARY_RESOLVE
        return true;
    }
    // The same for tools: exits with status 2 and the reason (and a hint, if given) on failure.
    void open_or_exit(const std::string& library, const char* hint = nullptr) {
        std::string why;
        if (!open(library, why)) {
            std::fprintf(stderr, "%s%s%s\n", why.c_str(), hint ? ": " : "", hint ? hint : "");
            std::exit(2);
        }
    }
    bool is_open() const { return so_ != nullptr; }
    void close() {
        if (so_ != nullptr) dlclose(so_);
        so_ = nullptr;
#define FMU_BINARY_CLEAR(name) name = nullptr;
        FMU_BINARY_FUNCTIONS(FMU_BINARY_CLEAR)
#undef FMU_BINARY_CLEAR
    }

private:
    void* so_ = nullptr;
};

}  // namespace fmu_binary
