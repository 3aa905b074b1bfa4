// fmuResourceLocation forms (fmu_src/fmi/resource_uri.hpp), each with POSIX and Windows rules:
// the function takes the platform as a parameter, so both sets run on every platform (and in
// the Windows cross-build under wine).
#include <gtest/gtest.h>

#include "fmi/resource_uri.hpp"

namespace {

std::string posix(const char* uri) { return fmi::resource_dir_from_uri(uri, false); }
std::string windows(const char* uri) { return fmi::resource_dir_from_uri(uri, true); }

TEST(ResourceUri, PosixFileUris) {
    EXPECT_EQ(posix("file:///tmp/fmu/resources"), "/tmp/fmu/resources");
    EXPECT_EQ(posix("file:///tmp/fmu/resources/"), "/tmp/fmu/resources");
    EXPECT_EQ(posix("file:/tmp/fmu/resources"), "/tmp/fmu/resources");
    EXPECT_EQ(posix("file://localhost/tmp/fmu/resources"), "/tmp/fmu/resources");
    EXPECT_EQ(posix("/tmp/fmu/resources/"), "/tmp/fmu/resources");  // a plain path, leniently
    EXPECT_EQ(posix("file:///"), "/");
}

TEST(ResourceUri, PercentEncodedUtf8) {
    EXPECT_EQ(posix("file:///tmp/my%20fmu/resources"), "/tmp/my fmu/resources");
    EXPECT_EQ(posix("file:///tmp/Mot%C3%B6r/r%C3%A9sources"), "/tmp/Mot\xC3\xB6r/r\xC3\xA9sources");
    EXPECT_EQ(windows("file:///C:/Users/J%C3%BCrgen/fmu/resources"), "C:/Users/J\xC3\xBCrgen/fmu/resources");
    EXPECT_EQ(posix("file:///tmp/%e6%97%a5%e6%9c%ac"), "/tmp/\xE6\x97\xA5\xE6\x9C\xAC");  // lower-case hex
}

TEST(ResourceUri, WindowsDriveUris) {
    EXPECT_EQ(windows("file:///C:/Users/a/fmu/resources"), "C:/Users/a/fmu/resources");
    EXPECT_EQ(windows("file:///C:/Users/a/fmu/resources/"), "C:/Users/a/fmu/resources");
    EXPECT_EQ(windows("file:/C:/Users/a/fmu/resources"), "C:/Users/a/fmu/resources");
    EXPECT_EQ(windows("file://localhost/D:/fmu/resources"), "D:/fmu/resources");
    EXPECT_EQ(windows("file:///C:/"), "C:/");
    // POSIX has no drives: /C:/x is an absolute path there
    EXPECT_EQ(posix("file:///C:/Users/a/fmu/resources"), "/C:/Users/a/fmu/resources");
}

TEST(ResourceUri, WindowsUncUris) {
    EXPECT_EQ(windows("file://server/share/fmu/resources"), "//server/share/fmu/resources");
    EXPECT_EQ(windows("file://server/share/fmu/resources/"), "//server/share/fmu/resources");
    EXPECT_EQ(windows("file://server/sh%20are/fmu"), "//server/sh are/fmu");
    EXPECT_EQ(windows("file://server"), "");                    // no share
    EXPECT_EQ(windows("file://server/"), "");                   // no share
    EXPECT_EQ(posix("file://server/share/fmu/resources"), "");  // a remote host: nothing local
}

TEST(ResourceUri, WindowsPlainPaths) {
    EXPECT_EQ(windows("C:\\Users\\a\\fmu\\resources"), "C:\\Users\\a\\fmu\\resources");
    EXPECT_EQ(windows("C:\\Users\\a\\fmu\\resources\\"), "C:\\Users\\a\\fmu\\resources");
    EXPECT_EQ(windows("C:/Users/a/fmu/resources"), "C:/Users/a/fmu/resources");
    EXPECT_EQ(windows("\\\\server\\share\\fmu"), "\\\\server\\share\\fmu");
    EXPECT_EQ(posix("C:\\Users\\a"), "");  // relative on POSIX
}

TEST(ResourceUri, Refused) {
    for (auto* f : {&posix, &windows}) {
        EXPECT_EQ((*f)(nullptr), "");
        EXPECT_EQ((*f)(""), "");
        EXPECT_EQ((*f)("relative/path"), "");
        EXPECT_EQ((*f)("http://example.com/fmu/resources"), "");
        EXPECT_EQ((*f)("file:///tmp/a%2"), "");         // truncated escape
        EXPECT_EQ((*f)("file:///tmp/a%zz"), "");        // not hex
        EXPECT_EQ((*f)("file:///tmp/a%00b"), "");       // an encoded NUL
        EXPECT_EQ((*f)("file:///tmp/a?query"), "");     // a query
        EXPECT_EQ((*f)("file:///tmp/a#fragment"), "");  // a fragment
    }
}

}  // namespace
