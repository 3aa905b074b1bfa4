// A dq quantity (current, voltage, flux linkage) as the complex space vector of rotor
// coordinates, x = x_d + j x_q (docs/spec/MATH.md), with the arithmetic the equations are
// written in: sums, real multiples, j x (a quarter turn ahead) and rotations by exp(j angle).
// Each operation is the componentwise one, in the order written, so code in Dq computes bit
// for bit what the same code on pairs of doubles computes.
#pragma once

#include <cmath>

namespace ipmsm {

struct Dq {
    double d = 0, q = 0;

    Dq& operator+=(const Dq& o) {
        d += o.d;
        q += o.q;
        return *this;
    }
    Dq& operator-=(const Dq& o) {
        d -= o.d;
        q -= o.q;
        return *this;
    }
    friend Dq operator+(const Dq& a, const Dq& b) { return {a.d + b.d, a.q + b.q}; }
    friend Dq operator-(const Dq& a, const Dq& b) { return {a.d - b.d, a.q - b.q}; }
    friend Dq operator*(double k, const Dq& a) { return {k * a.d, k * a.q}; }
    friend Dq operator/(const Dq& a, double k) { return {a.d / k, a.q / k}; }
    // j x: x turned ahead by a quarter turn, (-x_q, x_d)
    Dq j() const { return {-q, d}; }
    double abs() const { return std::hypot(d, q); }
};

// Multiplication by exp(j angle), held as its cosine c and sine s.
struct Rotation {
    double c = 1, s = 0;
    Dq operator()(const Dq& x) const { return {x.d * c - x.q * s, x.d * s + x.q * c}; }
    Rotation inverse() const { return {c, -s}; }
};

}  // namespace ipmsm
