// The k-d tree; see nearest_point.hpp.
#include "machine/nearest_point.hpp"

#include <algorithm>
#include <limits>
#include <stdexcept>

namespace ipmsm {

NearestPoint2D::NearestPoint2D(const std::vector<double>& x, const std::vector<double>& y) {
    if (x.size() != y.size()) throw std::invalid_argument("NearestPoint2D: x and y differ in length");
    if (x.size() > std::numeric_limits<std::uint32_t>::max()) throw std::invalid_argument("NearestPoint2D: too many");
    nodes_.resize(x.size());
    for (std::size_t i = 0; i < x.size(); ++i) nodes_[i] = {x[i], y[i], static_cast<std::uint32_t>(i)};
    build(0, nodes_.size(), 0);
    for (const Node& n : nodes_) {
        bounds_.x0 = std::min(bounds_.x0, n.x);
        bounds_.x1 = std::max(bounds_.x1, n.x);
        bounds_.y0 = std::min(bounds_.y0, n.y);
        bounds_.y1 = std::max(bounds_.y1, n.y);
    }
}

void NearestPoint2D::build(std::size_t lo, std::size_t hi, int axis) {
    if (hi - lo <= 1) return;
    const std::size_t mid = (lo + hi) / 2;
    std::nth_element(nodes_.begin() + lo, nodes_.begin() + mid, nodes_.begin() + hi,
                     [axis](const Node& a, const Node& b) { return axis == 0 ? a.x < b.x : a.y < b.y; });
    build(lo, mid, 1 - axis);
    build(mid + 1, hi, 1 - axis);
}

void NearestPoint2D::search(std::size_t lo, std::size_t hi, int axis, Box box, double x, double y, double& best,
                            std::ptrdiff_t& at, std::size_t& visits) const {
    if (lo >= hi) return;
    // Pruned on the distance to the subtree's cell (its splits within the points' bounding box),
    // not only to the splitting line: a query far outside then visits O(log N) cells, not a front.
    const double ex = std::max({box.x0 - x, x - box.x1, 0.0}), ey = std::max({box.y0 - y, y - box.y1, 0.0});
    if (ex * ex + ey * ey > best) return;
    const std::size_t mid = (lo + hi) / 2;
    const Node& n = nodes_[mid];
    ++visits;
    const double dx = n.x - x, dy = n.y - y, d2 = dx * dx + dy * dy;
    if (d2 < best || (d2 == best && static_cast<std::ptrdiff_t>(n.index) < at)) {
        best = d2;
        at = n.index;
    }
    Box left = box, right = box;
    if (axis == 0) {
        left.x1 = right.x0 = n.x;
    } else {
        left.y1 = right.y0 = n.y;
    }
    // The side holding the query first.
    if ((axis == 0 ? dx : dy) > 0) {
        search(lo, mid, 1 - axis, left, x, y, best, at, visits);
        search(mid + 1, hi, 1 - axis, right, x, y, best, at, visits);
    } else {
        search(mid + 1, hi, 1 - axis, right, x, y, best, at, visits);
        search(lo, mid, 1 - axis, left, x, y, best, at, visits);
    }
}

std::ptrdiff_t NearestPoint2D::nearest(double x, double y, std::size_t* visits) const {
    double best = std::numeric_limits<double>::infinity();
    std::ptrdiff_t at = -1;
    std::size_t v = 0;
    search(0, nodes_.size(), 0, bounds_, x, y, best, at, v);
    if (visits != nullptr) *visits = v;
    return at;
}

}  // namespace ipmsm
