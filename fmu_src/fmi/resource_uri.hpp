// fmuResourceLocation (a URI) to a local directory path, as UTF-8. FMI-free, header-only and
// platform-independent (the platform is a parameter), so that every form is unit-tested on
// every platform (tests/cpp/test_resource_uri.cpp), also when cross-compiled for Windows.
#pragma once

#include <cstddef>
#include <string>

namespace fmi {

#ifdef _WIN32
inline constexpr bool kWindowsPaths = true;
#else
inline constexpr bool kWindowsPaths = false;
#endif

namespace uri_detail {

inline bool is_drive(const std::string& s, std::size_t i) {  // "C:" then '/', '\' or the end
    const char c = i < s.size() ? s[i] : '\0';
    return ((c >= 'A' && c <= 'Z') || (c >= 'a' && c <= 'z')) && i + 1 < s.size() && s[i + 1] == ':' &&
           (i + 2 == s.size() || s[i + 2] == '/' || s[i + 2] == '\\');
}

inline bool starts(const std::string& s, const char* p) {
    return s.compare(0, std::char_traits<char>::length(p), p) == 0;
}

// Percent-decoding (bytes: %C3%A9 is UTF-8 é); "" for a bad escape, an encoded NUL, a query or
// a fragment (which have no meaning for a folder).
inline bool decode(const std::string& in, std::string& out) {
    out.clear();
    out.reserve(in.size());
    for (std::size_t i = 0; i < in.size(); ++i) {
        const char c = in[i];
        if (c == '?' || c == '#') return false;
        if (c != '%') {
            out += c;
            continue;
        }
        if (i + 2 >= in.size()) return false;
        int v = 0;
        for (int k = 1; k <= 2; ++k) {
            const char h = in[i + k];
            v *= 16;
            if (h >= '0' && h <= '9')
                v += h - '0';
            else if (h >= 'a' && h <= 'f')
                v += h - 'a' + 10;
            else if (h >= 'A' && h <= 'F')
                v += h - 'A' + 10;
            else
                return false;
        }
        if (v == 0) return false;
        out += static_cast<char>(v);
        i += 2;
    }
    return true;
}

inline std::string without_trailing_slashes(std::string s, std::size_t keep, bool windows) {
    while (s.size() > keep && (s.back() == '/' || (windows && s.back() == '\\'))) s.pop_back();
    return s;
}

}  // namespace uri_detail

// The directory that fmuResourceLocation names, without a trailing '/', or "" if it names none
// (NULL, a relative path, another scheme, a bad %-escape or an encoded NUL, a query or fragment,
// a remote host where there are no UNC paths). Understood, percent-encoded (UTF-8) or not:
//   file:///abs/path, file:/abs/path, file://localhost/abs/path      -> /abs/path
//   file:///C:/dir, file:/C:/dir, file://localhost/C:/dir            -> C:/dir   (windows)
//   file://host/share/dir (a UNC path)                               -> //host/share/dir (windows)
//   a plain absolute path /abs/path, and on Windows C:\dir, C:/dir, \\host\share\dir: as is
// (FMI 2.0 section 2.1.7 says a URI; importers on Windows pass file:///C:/..., some a plain path.)
inline std::string resource_dir_from_uri(const char* uri, bool windows = kWindowsPaths) {
    using namespace uri_detail;
    if (uri == nullptr) return "";
    const std::string s(uri);
    if (!s.empty() && s[0] == '/') return without_trailing_slashes(s, 1, windows);
    if (windows && is_drive(s, 0)) return without_trailing_slashes(s, 3, windows);
    if (windows && s.size() > 2 && s[0] == '\\' && s[1] == '\\') return without_trailing_slashes(s, 2, windows);
    std::string encoded, path;
    bool unc = false;
    if (starts(s, "file:///"))
        encoded = s.substr(7);
    else if (starts(s, "file://localhost/"))
        encoded = s.substr(16);
    else if (starts(s, "file://")) {
        encoded = s.substr(5);  // "//host/share/...": a UNC path
        unc = true;
    } else if (starts(s, "file:/"))
        encoded = s.substr(5);
    else
        return "";
    if (!decode(encoded, path)) return "";
    if (unc) {
        if (!windows) return "";  // no remote files on POSIX
        const std::size_t host_end = path.find('/', 2);
        if (host_end == 2 || host_end == std::string::npos || host_end + 1 >= path.size()) return "";
        return without_trailing_slashes(path, host_end + 1, windows);
    }
    if (windows && path.size() >= 3 && path[0] == '/' && is_drive(path, 1))
        return without_trailing_slashes(path.substr(1), 3, windows);  // "/C:/dir" -> "C:/dir"
    return without_trailing_slashes(path, 1, windows);
}

}  // namespace fmi
