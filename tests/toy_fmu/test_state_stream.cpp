// The encoding of a model's state fields (fmu_src/fmi/state_stream.hpp): what state_fields()
// lists is written and read by the same list, bit for bit, and bad bytes are refused.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <vector>

#include "state_stream.hpp"

namespace {

enum class Mode : int { off = 0, on = 7 };

struct Fields {
    double x = 0.0;
    double pair[2] = {0.0, 0.0};
    int n = 0;
    bool flag = false;
    Mode mode = Mode::off;

    template <class Field>
    void state_fields(Field&& field) {
        field(x), field(pair), field(n), field(flag), field(mode);
    }
};

Fields example() {
    Fields f;
    f.x = 0.1;
    f.pair[0] = -1e-300;
    f.pair[1] = 3.5;
    f.n = -42;
    f.flag = true;
    f.mode = Mode::on;
    return f;
}

// 8 (x) + 8 + 2 * 8 (pair: count, elements) + 4 (n) + 1 (flag) + 4 (mode)
constexpr std::size_t kBytes = 41;

}  // namespace

TEST(StateFields, RoundTripIsBitIdentical) {
    Fields a = example();
    const std::vector<char> bytes = fmi::save_state_fields(a);
    ASSERT_EQ(bytes.size(), kBytes);
    Fields b;
    fmi::load_state_fields(b, bytes.data(), bytes.size());
    EXPECT_EQ(std::memcmp(&a.x, &b.x, sizeof a.x), 0);
    EXPECT_EQ(std::memcmp(a.pair, b.pair, sizeof a.pair), 0);
    EXPECT_EQ(b.n, -42);
    EXPECT_TRUE(b.flag);
    EXPECT_EQ(b.mode, Mode::on);
    EXPECT_EQ(fmi::save_state_fields(b), bytes);
}

TEST(StateFields, BadBytesAreRefused) {
    Fields a = example();
    const std::vector<char> good = fmi::save_state_fields(a);
    Fields b;
    EXPECT_THROW(fmi::load_state_fields(b, good.data(), good.size() - 1), fmi::Error);  // truncated
    std::vector<char> longer = good;
    longer.push_back(0);
    EXPECT_THROW(fmi::load_state_fields(b, longer.data(), longer.size()), fmi::Error);  // trailing byte
    std::vector<char> nan = good;
    const double q = std::numeric_limits<double>::quiet_NaN();
    std::memcpy(nan.data(), &q, sizeof q);
    EXPECT_THROW(fmi::load_state_fields(b, nan.data(), nan.size()), fmi::Error);  // x not finite
    std::vector<char> count = good;
    count[8] = 3;  // the array's length
    EXPECT_THROW(fmi::load_state_fields(b, count.data(), count.size()), fmi::Error);
    std::vector<char> flag = good;
    flag[kBytes - 5] = 2;  // any non-zero byte reads as true, never as an invalid bool
    fmi::load_state_fields(b, flag.data(), flag.size());
    EXPECT_TRUE(b.flag);
}
