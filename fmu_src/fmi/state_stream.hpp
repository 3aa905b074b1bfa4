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

// A model's internal state as bytes, and back (a throw leaves m partly read: read into a copy).
template <class M>
std::vector<char> save_state_fields(M& m) {
    std::vector<char> block;
    StateWriter w(block);
    m.state_fields([&](auto& x) { write_field(w, x); });
    return block;
}

template <class M>
void load_state_fields(M& m, const char* data, std::size_t size) {
    StateReader r(data, size);
    m.state_fields([&](auto& x) { read_field(r, x); });
    if (!r.at_end()) throw Error("serialised FMU state: the model's state block is longer than its fields");
}

}  // namespace fmi
