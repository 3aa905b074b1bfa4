// The byte stream of a serialised FMU state (fmu_state.hpp): plain values in native byte order,
// strings and arrays prefixed with their length, and one encoding per field type of a model's
// state_fields() (model.hpp), used both ways: write_field() and read_field() are each other's
// inverse, so a model lists its state once.
#pragma once

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>
#include <vector>

#include "model.hpp"
#include "variable.hpp"

namespace fmi {

class StateWriter {
public:
    explicit StateWriter(std::vector<char>& out) : out_(out) {}
    template <class T>
    void put(const T& v) {
        static_assert(std::is_trivially_copyable_v<T>, "put() takes plain values");
        const char* p = reinterpret_cast<const char*>(&v);
        out_.insert(out_.end(), p, p + sizeof(T));
    }
    void put_string(const std::string& s) {
        put<std::uint64_t>(s.size());
        out_.insert(out_.end(), s.begin(), s.end());
    }

private:
    std::vector<char>& out_;
};

class StateReader {
public:
    StateReader(const char* data, std::size_t size) : p_(data), end_(data + size) {}
    template <class T>
    T get() {
        static_assert(std::is_trivially_copyable_v<T>, "get() takes plain values");
        need(sizeof(T));
        T v;
        std::memcpy(&v, p_, sizeof(T));
        p_ += sizeof(T);
        return v;
    }
    std::string get_string() {
        const auto n = get<std::uint64_t>();
        need(n);
        std::string s(p_, p_ + n);
        p_ += n;
        return s;
    }
    // An array of doubles (put_doubles): its count is checked against the bytes left before
    // anything is allocated for it.
    std::vector<double> get_doubles() {
        const auto n = get<std::uint64_t>();
        if (n > static_cast<std::uint64_t>(end_ - p_) / sizeof(double))
            throw Error("serialised FMU state is truncated");
        std::vector<double> x(n);
        if (n > 0) std::memcpy(x.data(), p_, n * sizeof(double));
        p_ += n * sizeof(double);
        return x;
    }
    bool at_end() const { return p_ == end_; }

private:
    void need(std::uint64_t n) const {
        if (static_cast<std::uint64_t>(end_ - p_) < n) throw Error("serialised FMU state is truncated");
    }
    const char* p_;
    const char* end_;
};

// One field of a model's internal state. bool: one byte 0 or 1 (its object representation
// is not read back: any other byte would be undefined behaviour); an enum: its underlying
// integer; T[N]: N, then the elements. A double read back must be finite: a model's state never
// holds NaN or infinity (the glue refuses to leave one in an output either).
template <class T>
void write_field(StateWriter& w, const T& x) {
    if constexpr (std::is_array_v<T>) {
        w.put<std::uint64_t>(std::extent_v<T>);
        for (const auto& e : x) write_field(w, e);
    } else if constexpr (std::is_same_v<T, bool>) {
        w.put<std::uint8_t>(x ? 1 : 0);
    } else if constexpr (std::is_enum_v<T>) {
        w.put(static_cast<std::underlying_type_t<T>>(x));
    } else {
        static_assert(std::is_same_v<T, double> || std::is_same_v<T, int>,
                      "state_fields() lists double, int, bool, enum members or fixed arrays of them");
        w.put(x);
    }
}

template <class T>
void read_field(StateReader& r, T& x) {
    if constexpr (std::is_array_v<T>) {
        if (r.get<std::uint64_t>() != std::extent_v<T>) throw Error("serialised FMU state: array size mismatch");
        for (auto& e : x) read_field(r, e);
    } else if constexpr (std::is_same_v<T, bool>) {
        x = r.get<std::uint8_t>() != 0;
    } else if constexpr (std::is_enum_v<T>) {
        x = static_cast<T>(r.get<std::underlying_type_t<T>>());
    } else {
        x = r.get<T>();
        if constexpr (std::is_same_v<T, double>)
            if (!std::isfinite(x)) throw Error("serialised FMU state: the model's internal state is not finite");
    }
}

// A field read back, checked against what it may hold (model.hpp): a range of the model's own
// (FieldRange), or a variable of a model's table, checked as fmi2SetReal/Integer check it. A state
// is input, not proof: its checksum guards against accidents, not against edits.
template <class T>
double field_number(const T& x) {
    if constexpr (std::is_enum_v<T>)
        return static_cast<double>(static_cast<std::underlying_type_t<T>>(x));
    else
        return static_cast<double>(x);
}

template <class T>
void check_field(const T& x, const FieldRange& range) {
    if constexpr (std::is_array_v<T>) {
        for (const auto& e : x) check_field(e, range);
    } else {
        const double v = field_number(x);
        if (!(v >= range.min && v <= range.max) || (range.whole && v != std::floor(v)))
            throw Error(std::string("serialised FMU state: ") + range.name + " = " + number_text(v) +
                        " is out of range: it must be " + (range.whole ? "a whole number in " : "in ") + "[" +
                        number_text(range.min) + ", " + number_text(range.max) + "]; not restored");
    }
}

template <class T, class Sub>
void check_field(const T& x, const Variable<Sub>& v) {
    if constexpr (std::is_same_v<T, double> || std::is_same_v<T, int>) {
        const std::string why = range_error(v, static_cast<double>(x));
        if (!why.empty()) throw Error("serialised FMU state: " + why + "; not restored");
    }
}

// A model's internal state as bytes, and back (a throw leaves m partly read: read into a copy).
template <class M>
std::vector<char> save_state_fields(M& m) {
    std::vector<char> block;
    StateWriter w(block);
    m.state_fields([&](auto& x, const auto&...) { write_field(w, x); });
    return block;
}

template <class M>
void load_state_fields(M& m, const char* data, std::size_t size) {
    StateReader r(data, size);
    m.state_fields([&](auto& x, const auto&... what_it_may_hold) {
        read_field(r, x);
        (check_field(x, what_it_may_hold), ...);
    });
    if (!r.at_end()) throw Error("serialised FMU state: the model's state block is longer than its fields");
}

}  // namespace fmi
