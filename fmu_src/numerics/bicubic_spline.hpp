// A C2 bicubic (tensor-product cubic) interpolating spline on a rectangular, possibly
// non-uniform grid, for one or more fields sharing the grid. Internal building block of
// FluxMap (psi_d, psi_q over i_d, i_q) and InverseFluxMap (i_d, i_q over psi_d, psi_q).
//
// Construction (de Boor): 1-D not-a-knot spline slopes along x for every grid line, along y
// for every grid column, then the cross derivative f_xy as the y-slopes of the x-slopes; each
// cell is then the bicubic Hermite patch of the corner values f, f_x, f_y, f_xy, stored as
// 16 monomial coefficients in local offsets (x - x_j, y - y_k), so evaluation is a few dozen
// multiply-adds per field and needs no scaling. The patches together are exactly the
// tensor-product C2 spline interpolant (values, first and second derivatives continuous).
//
// End conditions: not-a-knot on both axes (third derivative continuous across the second and
// the second-last node). It needs no end-slope data, reproduces cubics exactly (so linear
// maps to rounding), and on smooth data its end cells are as accurate as the interior, unlike
// the natural spline, which forces f'' = 0 at the edge of a saturation curve. Axes of 3 nodes
// get the interpolating parabola, axes of 2 nodes the straight line.
//
// Outside the grid: each 1-D cubic basis (1, u, u^2, u^3) of the edge cell is continued by its
// tangent beyond the grid's end, so the surface is continued linearly from the nearest boundary
// point: f(xb, y) + f_x(xb, y) (x - xb) beyond an edge, and the bilinear
// f + f_x dx + f_y dy + f_xy dx dy beyond a corner. Values and first derivatives are continuous
// everywhere (C1); the second derivative along the outward normal is zero outside, and every
// derivative returned is the exact derivative of the value returned (also outside), and eval
// and eval2 share one code path, so their common outputs agree bit for bit.
//
// Cell lookup is O(1) on uniform axes (every node within kUniformAxisTolerance of a spacing of
// its uniform position) and a binary search otherwise. Evaluation allocates nothing and is safe
// for NaN/huge arguments (NaN in, NaN out).
#pragma once

#include <algorithm>
#include <cstddef>
#include <vector>

namespace ipmsm {

// Value and first derivatives of one field at one point.
struct SplineValue {
    double f, fx, fy;
};
// ... plus second derivatives.
struct SplineValue2 {
    double f, fx, fy, fxx, fxy, fyy;
};

class BicubicSpline2D {
public:
    static constexpr double kUniformAxisTolerance = 1e-6;  // of a spacing (bicubic_spline.cpp)

    BicubicSpline2D() = default;

    // x: nx >= 2 strictly ascending finite values, y likewise (ny >= 2). fields: pointers to
    // nx * ny values each, the value at (x[j], y[k]) at [k * nx + j]. Throws
    // std::invalid_argument on bad axes or non-finite values.
    BicubicSpline2D(const std::vector<double>& x, const std::vector<double>& y,
                    const std::vector<const double*>& fields);

    int num_fields() const { return nf_; }
    const std::vector<double>& x() const { return ax_.v; }
    const std::vector<double>& y() const { return ay_.v; }
    bool uniform_x() const { return ax_.uniform; }
    bool uniform_y() const { return ay_.uniform; }
    std::size_t memory_bytes() const { return (coef_.size() + ax_.v.size() + ay_.v.size()) * sizeof(double); }

    // All NF fields (NF must equal num_fields()) at (x, y).
    template <int NF>
    void eval(double x, double y, SplineValue (&out)[NF]) const;
    template <int NF>
    void eval2(double x, double y, SplineValue2 (&out)[NF]) const;

    // 1-D not-a-knot spline slopes s[i] = f'(x[i]) of the data f[i * stride], i < n (n >= 2;
    // n = 2: the chord, n = 3: the parabola). Written to s[i * stride]. Exact for cubics.
    static void spline_slopes(const double* x, int n, const double* f, int stride, double* s);

private:
    struct Axis {
        std::vector<double> v;
        bool uniform = false;
        double v0 = 0, inv_h = 0;  // first node, 1 / spacing (uniform only)
        double h_last = 0;         // width of the last cell
        int n_cells = 0;
        void init(const std::vector<double>& values);
        // Cell index j in [0, n_cells - 1] and local offset u = t - v[j].
        int locate(double t, double& u) const;
    };
    // Basis (1, u, u^2, u^3) with its first and second derivatives, continued by the tangent
    // outside the grid (side < 0: before the first node, > 0: past the last).
    static void basis(double u, double h_last, int side, double b[4], double d[4], double dd[4]);
    // eval and eval2 share this code, so their values and first derivatives agree bit for bit.
    template <int NF, bool Second, class Out>
    void eval_impl(double x, double y, Out* out) const;

    Axis ax_, ay_;
    int nf_ = 0;
    std::vector<double> coef_;  // per cell (k * (nx-1) + j): for each field, a[m * 4 + n] of u^m v^n
};

// ---------------------------------------------------------------------------------------------
// Inline evaluation (hot path).

inline int BicubicSpline2D::Axis::locate(double t, double& u) const {
    int j;
    if (uniform) {
        const double s = (t - v0) * inv_h;
        // Written so that NaN and huge arguments give a valid index without UB.
        j = s > 0.0 ? (s < static_cast<double>(n_cells - 1) ? static_cast<int>(s) : n_cells - 1) : 0;
    } else {
        // Branch-free binary search: the last j in [0, n_cells - 1] with v[j] <= t (0 if none
        // or NaN); t in [v[j], v[j+1]) inside the grid.
        const double* p = v.data();
        j = 0;
        for (int len = n_cells; len > 1;) {
            const int half = len / 2;
            j = p[j + half] <= t ? j + half : j;
            len -= half;
        }
    }
    u = t - v[j];
    return j;
}

inline void BicubicSpline2D::basis(double u, double h_last, int side, double b[4], double d[4], double dd[4]) {
    b[0] = 1.0;
    d[0] = 0.0;
    dd[0] = 0.0;
    b[1] = u;
    d[1] = 1.0;
    dd[1] = 0.0;
    if (side == 0) {
        const double u2 = u * u;
        b[2] = u2;
        b[3] = u2 * u;
        d[2] = 2.0 * u;
        d[3] = 3.0 * u2;
        dd[2] = 2.0;
        dd[3] = 6.0 * u;
    } else if (side < 0) {  // u < 0, tangent at u = 0
        b[2] = b[3] = 0.0;
        d[2] = d[3] = 0.0;
        dd[2] = dd[3] = 0.0;
    } else {  // u > h, tangent at u = h
        const double h = h_last, h2 = h * h, e = u - h;
        b[2] = h2 + 2.0 * h * e;
        b[3] = h2 * h + 3.0 * h2 * e;
        d[2] = 2.0 * h;
        d[3] = 3.0 * h2;
        dd[2] = dd[3] = 0.0;
    }
}

template <int NF, bool Second, class Out>
inline void BicubicSpline2D::eval_impl(double x, double y, Out* out) const {
    double u, v;
    const int j = ax_.locate(x, u);
    const int k = ay_.locate(y, v);
    const double* a = coef_.data() + static_cast<std::size_t>(k * ax_.n_cells + j) * (16 * NF);
    const int sx = x < ax_.v.front() ? -1 : (x > ax_.v.back() ? 1 : 0);
    const int sy = y < ay_.v.front() ? -1 : (y > ay_.v.back() ? 1 : 0);
    double bx[4], dx[4], ddx[4], by[4], dy[4], ddy[4];
    basis(u, ax_.h_last, sx, bx, dx, ddx);
    basis(v, ay_.h_last, sy, by, dy, ddy);
    // f = bx^T A by, f_x = dx^T A by, f_y = bx^T A dy, ... (A: the cell's 4 x 4 coefficients).
    for (int f = 0; f < NF; ++f, a += 16) {
        double val = 0, gx = 0, gy = 0, hxx = 0, hxy = 0, hyy = 0;
        for (int m = 0; m < 4; ++m) {
            const double* r = a + 4 * m;
            const double p = r[0] * by[0] + r[1] * by[1] + r[2] * by[2] + r[3] * by[3];
            const double q = r[0] * dy[0] + r[1] * dy[1] + r[2] * dy[2] + r[3] * dy[3];
            val += bx[m] * p;
            gx += dx[m] * p;
            gy += bx[m] * q;
            if (Second) {
                const double w = r[0] * ddy[0] + r[1] * ddy[1] + r[2] * ddy[2] + r[3] * ddy[3];
                hxx += ddx[m] * p;
                hxy += dx[m] * q;
                hyy += bx[m] * w;
            }
        }
        out[f].f = val;
        out[f].fx = gx;
        out[f].fy = gy;
        if constexpr (Second) {
            out[f].fxx = hxx;
            out[f].fxy = hxy;
            out[f].fyy = hyy;
        }
    }
}

template <int NF>
inline void BicubicSpline2D::eval(double x, double y, SplineValue (&out)[NF]) const {
    eval_impl<NF, false>(x, y, out);
}

template <int NF>
inline void BicubicSpline2D::eval2(double x, double y, SplineValue2 (&out)[NF]) const {
    eval_impl<NF, true>(x, y, out);
}

}  // namespace ipmsm
