// C2 bicubic spline: construction (see bicubic_spline.hpp for the method and its choices).
#include "numerics/bicubic_spline.hpp"

#include <cmath>
#include <cstddef>
#include <stdexcept>
#include <string>

namespace ipmsm {

void BicubicSpline2D::Axis::init(const std::vector<double>& values) {
    const int n = static_cast<int>(values.size());
    if (n < 2) throw std::invalid_argument("BicubicSpline2D: an axis needs at least 2 nodes");
    for (int i = 0; i < n; ++i) {
        if (!std::isfinite(values[i])) throw std::invalid_argument("BicubicSpline2D: non-finite axis value");
        if (i > 0 && !(values[i] > values[i - 1]))
            throw std::invalid_argument("BicubicSpline2D: axis not strictly ascending at node " + std::to_string(i));
    }
    v = values;
    n_cells = n - 1;
    h_last = v[n - 1] - v[n - 2];
    const double h = (v[n - 1] - v[0]) / n_cells;
    // Uniform if every node is within kUniformAxisTolerance of a spacing of its uniform position.
    // The local offset is always taken from the stored node, so the tolerance only decides which
    // of two C2-joined patches evaluates a point that close to a node: they differ there by the
    // jump of the third derivative times (1e-6 h)^3 / 6, far below rounding. Axes printed with ten
    // significant digits (SyR-e's maps through `map import`: 3e-10 h off) are uniform.
    uniform = true;
    for (int i = 1; i < n - 1 && uniform; ++i) uniform = std::abs(v[i] - (v[0] + i * h)) <= kUniformAxisTolerance * h;
    v0 = v[0];
    inv_h = 1.0 / h;
}

void BicubicSpline2D::spline_slopes(const double* x, int n, const double* f, int stride, double* s) {
    if (n < 2) throw std::invalid_argument("spline_slopes: n < 2");
    auto F = [&](int i) { return f[static_cast<std::ptrdiff_t>(i) * stride]; };
    auto S = [&](int i) -> double& { return s[static_cast<std::ptrdiff_t>(i) * stride]; };
    if (n == 2) {
        const double d = (F(1) - F(0)) / (x[1] - x[0]);
        S(0) = S(1) = d;
        return;
    }
    if (n == 3) {  // the parabola through the three points
        const double h0 = x[1] - x[0], h1 = x[2] - x[1];
        const double d0 = (F(1) - F(0)) / h0, d1 = (F(2) - F(1)) / h1;
        const double c = (d1 - d0) / (h0 + h1);  // half the second derivative
        S(0) = d0 - c * h0;
        S(1) = d0 + c * h0;
        S(2) = d1 + c * h1;
        return;
    }
    // Not-a-knot tridiagonal system (as in de Boor's CUBSPL / MATLAB spline), solved by
    // elimination without pivoting (the eliminated pivots stay positive for any spacing).
    // Row i: sub[i] s[i-1] + dia[i] s[i] + sup[i] s[i+1] = rhs[i].
    // Small fixed-size work arrays on the stack for typical grids, heap otherwise.
    constexpr int kStack = 256;
    double buf[4 * kStack];
    std::vector<double> heap;
    double* w = buf;
    if (n > kStack) {
        heap.resize(4 * static_cast<std::size_t>(n));
        w = heap.data();
    }
    double *sub = w, *dia = w + n, *sup = w + 2 * n, *rhs = w + 3 * n;
    auto h = [&](int i) { return x[i + 1] - x[i]; };
    auto del = [&](int i) { return (F(i + 1) - F(i)) / h(i); };
    {
        const double h0 = h(0), h1 = h(1), x31 = h0 + h1;
        sub[0] = 0.0;
        dia[0] = h1;
        sup[0] = x31;
        rhs[0] = ((h0 + 2.0 * x31) * h1 * del(0) + h0 * h0 * del(1)) / x31;
    }
    for (int i = 1; i < n - 1; ++i) {
        const double hl = h(i - 1), hr = h(i);
        sub[i] = hr;
        dia[i] = 2.0 * (hl + hr);
        sup[i] = hl;
        rhs[i] = 3.0 * (hr * del(i - 1) + hl * del(i));
    }
    {
        const double ha = h(n - 3), hb = h(n - 2), xn = ha + hb;
        sub[n - 1] = xn;
        dia[n - 1] = ha;
        sup[n - 1] = 0.0;
        rhs[n - 1] = (hb * hb * del(n - 3) + (2.0 * xn + hb) * ha * del(n - 2)) / xn;
    }
    for (int i = 1; i < n; ++i) {
        const double m = sub[i] / dia[i - 1];
        dia[i] -= m * sup[i - 1];
        rhs[i] -= m * rhs[i - 1];
    }
    S(n - 1) = rhs[n - 1] / dia[n - 1];
    for (int i = n - 2; i >= 0; --i) S(i) = (rhs[i] - sup[i] * S(i + 1)) / dia[i];
}

BicubicSpline2D::BicubicSpline2D(const std::vector<double>& x, const std::vector<double>& y,
                                 const std::vector<const double*>& fields) {
    ax_.init(x);
    ay_.init(y);
    nf_ = static_cast<int>(fields.size());
    if (nf_ < 1) throw std::invalid_argument("BicubicSpline2D: no fields");
    const int nx = static_cast<int>(x.size()), ny = static_cast<int>(y.size());
    const std::size_t N = static_cast<std::size_t>(nx) * ny;
    const int cx = nx - 1, cy = ny - 1;
    coef_.assign(static_cast<std::size_t>(cx) * cy * 16 * nf_, 0.0);
    std::vector<double> fx(N), fy(N), fxy(N);

    for (int f = 0; f < nf_; ++f) {
        const double* F = fields[f];
        for (std::size_t i = 0; i < N; ++i)
            if (!std::isfinite(F[i]))
                throw std::invalid_argument("BicubicSpline2D: non-finite value in field " + std::to_string(f));
        for (int k = 0; k < ny; ++k)  // d/dx along each grid line y = y[k]
            spline_slopes(x.data(), nx, F + static_cast<std::size_t>(k) * nx, 1,
                          fx.data() + static_cast<std::size_t>(k) * nx);
        for (int j = 0; j < nx; ++j) {  // d/dy along each column, of f and of f_x
            spline_slopes(y.data(), ny, F + j, nx, fy.data() + j);
            spline_slopes(y.data(), ny, fx.data() + j, nx, fxy.data() + j);
        }
        for (int k = 0; k < cy; ++k) {
            const double hy = y[k + 1] - y[k];
            for (int j = 0; j < cx; ++j) {
                const double hx = x[j + 1] - x[j];
                const std::size_t i00 = static_cast<std::size_t>(k) * nx + j, i10 = i00 + 1, i01 = i00 + nx,
                                  i11 = i01 + 1;
                // G[r][s]: r = (f at x0, f at x1, d/dx at x0, d/dx at x1), s likewise in y.
                const double G[4][4] = {
                    {F[i00], F[i01], fy[i00], fy[i01]},
                    {F[i10], F[i11], fy[i10], fy[i11]},
                    {fx[i00], fx[i01], fxy[i00], fxy[i01]},
                    {fx[i10], fx[i11], fxy[i10], fxy[i11]},
                };
                // Cubic Hermite in monomials of the local offset: a = H g, g = (p0, p1, p0', p1').
                auto hermite = [](double h, double H[4][4]) {
                    const double h2 = h * h, h3 = h2 * h;
                    const double r[4][4] = {{1, 0, 0, 0},
                                            {0, 0, 1, 0},
                                            {-3 / h2, 3 / h2, -2 / h, -1 / h},
                                            {2 / h3, -2 / h3, 1 / h2, 1 / h2}};
                    for (int a = 0; a < 4; ++a)
                        for (int b = 0; b < 4; ++b) H[a][b] = r[a][b];
                };
                double Hx[4][4], Hy[4][4], T[4][4];
                hermite(hx, Hx);
                hermite(hy, Hy);
                for (int m = 0; m < 4; ++m)  // T = Hx G
                    for (int s = 0; s < 4; ++s) {
                        double acc = 0;
                        for (int r = 0; r < 4; ++r) acc += Hx[m][r] * G[r][s];
                        T[m][s] = acc;
                    }
                double* a = coef_.data() + (static_cast<std::size_t>(k) * cx + j) * 16 * nf_ + 16 * f;
                for (int m = 0; m < 4; ++m)  // A = T Hy^T
                    for (int n = 0; n < 4; ++n) {
                        double acc = 0;
                        for (int s = 0; s < 4; ++s) acc += T[m][s] * Hy[n][s];
                        a[4 * m + n] = acc;
                    }
            }
        }
    }
}

}  // namespace ipmsm
