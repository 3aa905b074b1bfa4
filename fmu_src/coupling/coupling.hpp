// The coupling description (ipmsm_drive.coupling, its syntax and semantics stated there), read
// into names: which units, in which order, which output feeds which input, which external input
// feeds which inputs. FMI-free: a master resolves the names to value references from the model
// descriptions, an FMU that holds both models (IpmsmDrive) to its models' fields. The reference
// loop (scenarios/cosim/reference.py) reads the same file in Python (scenarios/cosim/coupling.py).
#pragma once

#include <cctype>
#include <cmath>
#include <cstdlib>
#include <set>
#include <sstream>
#include <stdexcept>
#include <string>
#include <vector>

namespace ipmsm::coupling {

// A variable of a unit, "plant.i_d".
struct Port {
    std::string unit, variable;
    std::string text() const { return unit + "." + variable; }
};

struct Unit {
    std::string role;              // "plant", "controller"
    std::string model_identifier;  // the FMU's model identifier
};

struct Connection {
    Port from, to;  // an output, the input it feeds
};

struct ExternalInput {
    std::string name;      // "w_m"
    std::vector<Port> to;  // the inputs it feeds
};

struct Coupling {
    std::vector<Unit> units;  // in the order of initialisation and stepping
    double step = 0.0;        // s, the default communication step
    std::vector<Connection> connections;
    std::vector<ExternalInput> inputs;

    // Position of the unit in `units`, -1 if there is none of that role.
    int unit_index(const std::string& role) const {
        for (std::size_t i = 0; i < units.size(); ++i)
            if (units[i].role == role) return static_cast<int>(i);
        return -1;
    }
};

namespace detail {

inline std::string trim(const std::string& s) {
    const std::size_t a = s.find_first_not_of(" \t\r");
    if (a == std::string::npos) return "";
    return s.substr(a, s.find_last_not_of(" \t\r") - a + 1);
}

inline bool is_name(const std::string& s) {
    if (s.empty() || !(std::isalpha(static_cast<unsigned char>(s[0])) || s[0] == '_')) return false;
    for (unsigned char ch : s)
        if (!(std::isalnum(ch) || ch == '_')) return false;
    return true;
}

}  // namespace detail

// Reads a description; std::invalid_argument names the line and what is wrong with it.
inline Coupling parse(const std::string& text) {
    using detail::is_name;
    using detail::trim;
    Coupling c;
    std::set<std::string> fed;  // inputs already fed: each input has one source
    std::istringstream in(text);
    std::string raw;
    int line_no = 0;
    auto fail = [&](const std::string& why) {
        throw std::invalid_argument("coupling description, line " + std::to_string(line_no) + " (" + trim(raw) +
                                    "): " + why);
    };
    auto port = [&](const std::string& s) {
        const std::string t = trim(s);
        const std::size_t dot = t.find('.');
        if (dot == std::string::npos) fail("'" + t + "' is not ROLE.VARIABLE");
        Port p{t.substr(0, dot), t.substr(dot + 1)};
        if (c.unit_index(p.unit) < 0) fail("no unit '" + p.unit + "' (declare it with a unit line first)");
        if (!is_name(p.variable)) fail("'" + p.variable + "' is not a variable name");
        return p;
    };
    auto feed = [&](const Port& p) {
        if (!fed.insert(p.text()).second) fail(p.text() + " is fed twice");
    };
    while (std::getline(in, raw)) {
        ++line_no;
        const std::string line = trim(raw.substr(0, raw.find('#')));
        if (line.empty()) continue;
        std::istringstream words(line);
        std::string first;
        words >> first;
        if (first == "unit") {
            Unit u;
            std::string extra;
            if (!(words >> u.role >> u.model_identifier) || (words >> extra))
                fail("expected: unit ROLE MODEL_IDENTIFIER");
            if (!is_name(u.role) || !is_name(u.model_identifier)) fail("a role and a model identifier are names");
            if (c.unit_index(u.role) >= 0) fail("unit '" + u.role + "' declared twice");
            c.units.push_back(u);
        } else if (first == "step") {
            std::string value, extra;
            if (!(words >> value) || (words >> extra)) fail("expected: step SECONDS");
            char* end = nullptr;
            c.step = std::strtod(value.c_str(), &end);
            if (*end != '\0' || !std::isfinite(c.step) || c.step <= 0.0) fail("the step must be a number > 0");
        } else {
            const std::size_t arrow = line.find("->");
            if (arrow == std::string::npos)
                fail("expected: unit, step, ROLE.OUTPUT -> ROLE.INPUT or NAME -> ROLE.INPUT, ...");
            const std::string source = trim(line.substr(0, arrow));
            std::vector<Port> targets;
            std::istringstream list(line.substr(arrow + 2));
            for (std::string item; std::getline(list, item, ',');) targets.push_back(port(item));
            if (targets.empty()) fail("no input after '->'");
            if (source.find('.') != std::string::npos) {
                if (targets.size() != 1) fail("a connection feeds one input");
                const Port from = port(source);
                if (from.unit == targets[0].unit) fail("a connection joins two units");
                feed(targets[0]);
                c.connections.push_back({from, targets[0]});
            } else {
                if (!is_name(source)) fail("'" + source + "' is not an input name");
                for (const ExternalInput& e : c.inputs)
                    if (e.name == source) fail("external input '" + source + "' declared twice");
                for (const Port& p : targets) feed(p);
                c.inputs.push_back({source, targets});
            }
        }
    }
    if (c.units.empty()) throw std::invalid_argument("coupling description: no units");
    if (c.step == 0.0) throw std::invalid_argument("coupling description: no step");
    return c;
}

}  // namespace ipmsm::coupling
