// Importing an unzipped FMU in C++: the GUID and value references of its modelDescription.xml
// (read with a plain attribute search, enough for the files this project generates), and its
// binary's FMI 2.0 co-simulation functions, dlopened. Written once for every C++ importer in the
// repository: the plant benchmark
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

// What a master needs of a model description: the GUID, the co-simulation model identifier,
// each variable's value reference and type ("Real", "Integer", "Boolean", "String",
// "Enumeration").
struct Description {
    std::string guid, model_identifier;
    std::map<std::string, fmi2ValueReference> vr;
    std::map<std::string, std::string> type;
};

// Reads <dir>/modelDescription.xml into d; false, with why, if it cannot be read.
inline bool parse_description(const std::string& dir, Description& d, std::string& why) {
    std::ifstream f(dir + "/modelDescription.xml");
    std::stringstream ss;
    ss << f.rdbuf();
    const std::string xml = ss.str();
    d = Description{};
    d.guid = attribute_after(xml, 0, "guid");
    d.model_identifier = attribute_after(xml, xml.find("<CoSimulation"), "modelIdentifier");
    for (std::size_t p = xml.find("<ScalarVariable"); p != std::string::npos; p = xml.find("<ScalarVariable", p + 1)) {
        const std::string name = attribute_after(xml, p, "name");
        const std::string vr = attribute_after(xml, p, "valueReference");
        if (name.empty() || vr.empty() || vr.find_first_not_of("0123456789") != std::string::npos) continue;
        d.vr[name] = static_cast<fmi2ValueReference>(std::stoul(vr));
        // the type is the first child element (a raw '<' cannot occur in an attribute value)
        const std::size_t child = xml.find('<', p + 1);
        if (child != std::string::npos) {
            const std::size_t end = xml.find_first_of(" \t\r\n/>", child + 1);
            d.type[name] = xml.substr(child + 1, end - child - 1);
        }
    }
    if (d.guid.empty() || d.vr.empty()) {
        why = "cannot read " + dir + "/modelDescription.xml";
        return false;
    }
    return true;
}

// The same for tools: exits with status 2 and a message if it cannot be read.
inline Description read_description(const std::string& dir) {
    Description d;
    std::string why;
    if (!parse_description(dir, d, why)) {
        std::fprintf(stderr, "%s\n", why.c_str());
        std::exit(2);
    }
    return d;
}

// The binary of an unzipped FMU for this platform.
inline std::string library_path(const std::string& dir, const std::string& model_identifier) {
    return dir + "/binaries/linux64/" + model_identifier + ".so";
}

// Every FMI 2.0 function a co-simulation FMU exports, each named as in the standard.
#define FMU_BINARY_FUNCTIONS(X)     \
    X(fmi2GetTypesPlatform)         \
    X(fmi2GetVersion)               \
    X(fmi2SetDebugLogging)          \
    X(fmi2Instantiate)              \
    X(fmi2FreeInstance)             \
    X(fmi2SetupExperiment)          \
    X(fmi2EnterInitializationMode)  \
    X(fmi2ExitInitializationMode)   \
    X(fmi2Terminate)                \
    X(fmi2Reset)                    \
    X(fmi2GetReal)                  \
    X(fmi2GetInteger)               \
    X(fmi2GetBoolean)               \
    X(fmi2GetString)                \
    X(fmi2SetReal)                  \
    X(fmi2SetInteger)               \
    X(fmi2SetBoolean)               \
    X(fmi2SetString)                \
    X(fmi2GetFMUstate)              \
    X(fmi2SetFMUstate)              \
    X(fmi2FreeFMUstate)             \
    X(fmi2SerializedFMUstateSize)   \
    X(fmi2SerializeFMUstate)        \
    X(fmi2DeSerializeFMUstate)      \
    X(fmi2GetDirectionalDerivative) \
    X(fmi2SetRealInputDerivatives)  \
    X(fmi2GetRealOutputDerivatives) \
    X(fmi2DoStep)                   \
    X(fmi2CancelStep)               \
    X(fmi2GetStatus)                \
    X(fmi2GetRealStatus)            \
    X(fmi2GetIntegerStatus)         \
    X(fmi2GetBooleanStatus)         \
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
#define FMU_BINARY_RESOLVE(name)                             \
    name = reinterpret_cast<name##TYPE*>(dlsym(so_, #name)); \
    if (name == nullptr) {                                   \
        why = library + " does not export " #name;           \
        close();                                             \
        return false;                                        \
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
