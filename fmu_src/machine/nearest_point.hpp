// The nearest of a fixed set of points in the plane: a balanced k-d tree (Bentley 1975), built in
// O(N log N), a query in O(log N) for points spread like a flux map's nodes (the inverse map's
// start guess beyond its table: inverse_flux_map.hpp). Exact: the same distance as a scan.
#pragma once

#include <cstddef>
#include <cstdint>
#include <limits>
#include <vector>

namespace ipmsm {

class NearestPoint2D {
public:
    NearestPoint2D() = default;
    // x[i], y[i]: the points, in the units the distance is measured in.
    NearestPoint2D(const std::vector<double>& x, const std::vector<double>& y);

    // The index of a point nearest (x, y) (Euclidean); -1 when there are none. visits (optional)
    // counts the points whose distance was computed.
    std::ptrdiff_t nearest(double x, double y, std::size_t* visits = nullptr) const;
    std::size_t size() const { return nodes_.size(); }

private:
    struct Node {
        double x, y;
        std::uint32_t index;
    };
    void build(std::size_t lo, std::size_t hi, int axis);
    struct Box {
        double x0 = kInf, x1 = -kInf, y0 = kInf, y1 = -kInf;
    };
    static constexpr double kInf = std::numeric_limits<double>::infinity();
    void search(std::size_t lo, std::size_t hi, int axis, Box box, double x, double y, double& best, std::ptrdiff_t& at,
                std::size_t& visits) const;
    std::vector<Node> nodes_;  // the subtree of [lo, hi) has its root at (lo + hi) / 2
    Box bounds_;               // of all the points
};

}  // namespace ipmsm
