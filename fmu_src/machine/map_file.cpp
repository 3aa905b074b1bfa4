// Bounded reading of data files; see map_file.hpp.
#include "machine/map_file.hpp"

#include <cctype>
#include <cerrno>
#include <cstdio>
#include <cstring>
#include <memory>

#include "fmi/log_text.hpp"

#ifdef _WIN32
#include <sys/stat.h>
#include <sys/types.h>
#include <windows.h>
#else
#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>
#endif

namespace ipmsm {
namespace {

std::string too_large(std::size_t max_bytes) {
    return "larger than " + std::to_string(max_bytes) + " bytes, the limit for a flux map";
}

#ifdef _WIN32
std::wstring widen(const std::string& utf8) {
    if (utf8.empty()) return std::wstring();
    const int n =
        MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, utf8.data(), static_cast<int>(utf8.size()), nullptr, 0);
    if (n <= 0) throw MapFileError("cannot open file (the path is not valid UTF-8)");
    std::wstring w(static_cast<std::size_t>(n), L'\0');
    MultiByteToWideChar(CP_UTF8, MB_ERR_INVALID_CHARS, utf8.data(), static_cast<int>(utf8.size()), &w[0], n);
    return w;
}

std::string read_regular(const std::string& path, std::size_t max_bytes) {
    const std::wstring w = widen(path);
    struct _stat64 st;
    if (_wstat64(w.c_str(), &st) != 0)
        throw MapFileError(std::string("cannot open file (") + std::strerror(errno) + ")");
    if ((st.st_mode & _S_IFMT) == _S_IFDIR) throw MapFileError("cannot open file (it is a directory)");
    if ((st.st_mode & _S_IFMT) != _S_IFREG) throw MapFileError("cannot open file (not a regular file)");
    if (static_cast<unsigned long long>(st.st_size) > max_bytes) throw MapFileError(too_large(max_bytes));
    std::unique_ptr<FILE, int (*)(FILE*)> f(_wfopen(w.c_str(), L"rb"), &std::fclose);
    if (!f) throw MapFileError(std::string("cannot open file (") + std::strerror(errno) + ")");
    std::string bytes;
    char buf[65536];
    for (std::size_t n; (n = std::fread(buf, 1, sizeof buf, f.get())) > 0;) {
        if (bytes.size() + n > max_bytes) throw MapFileError(too_large(max_bytes));
        bytes.append(buf, n);
    }
    if (std::ferror(f.get())) throw MapFileError("read error");
    return bytes;
}
#else
std::string read_regular(const std::string& path, std::size_t max_bytes) {
    // O_NONBLOCK: opening a FIFO without a writer would otherwise wait for one forever.
    const int fd = ::open(path.c_str(), O_RDONLY | O_NONBLOCK | O_CLOEXEC);
    if (fd < 0) throw MapFileError(std::string("cannot open file (") + std::strerror(errno) + ")");
    struct Closer {
        int fd;
        ~Closer() { ::close(fd); }
    } closer{fd};
#ifdef __GLIBC__
    // fstat64: the symbol every glibc has (the FMUs' glibc_compat wraps it); fstat is 2.33's
    struct stat64 st;
    const int stat_result = ::fstat64(fd, &st);
#else
    struct stat st;
    const int stat_result = ::fstat(fd, &st);
#endif
    if (stat_result != 0) throw MapFileError(std::string("cannot open file (") + std::strerror(errno) + ")");
    if (S_ISDIR(st.st_mode)) throw MapFileError("cannot open file (it is a directory)");
    if (S_ISFIFO(st.st_mode)) throw MapFileError("not a regular file (a named pipe)");
    if (S_ISCHR(st.st_mode) || S_ISBLK(st.st_mode)) throw MapFileError("not a regular file (a device)");
    if (!S_ISREG(st.st_mode)) throw MapFileError("not a regular file");
    if (static_cast<unsigned long long>(st.st_size) > max_bytes) throw MapFileError(too_large(max_bytes));
    std::string bytes;
    bytes.reserve(static_cast<std::size_t>(st.st_size));
    char buf[65536];
    for (;;) {
        const ssize_t n = ::read(fd, buf, sizeof buf);
        if (n < 0) {
            if (errno == EINTR) continue;
            throw MapFileError(std::string("read error (") + std::strerror(errno) + ")");
        }
        if (n == 0) break;
        if (bytes.size() + static_cast<std::size_t>(n) > max_bytes) throw MapFileError(too_large(max_bytes));
        bytes.append(buf, static_cast<std::size_t>(n));
    }
    return bytes;
}
#endif

}  // namespace

std::string read_map_file(const std::string& utf8_path, std::size_t max_bytes) {
    return read_regular(utf8_path, max_bytes);
}

std::string quoted_excerpt(const std::string& text, std::size_t max_chars) {
    return fmi::utf8_excerpt(text, max_chars);
}

std::string describe_token(const std::string& token) {
    if (token.empty()) return "empty";
    bool printable = true, blank = false, digits = true;
    for (unsigned char c : token) {
        printable = printable && c >= 0x20 && c < 0x7f;
        blank = blank || c == ' ' || c == '\t';
        digits = digits && (std::isdigit(c) || c == '.' || c == '-' || c == '+' || c == 'e' || c == 'E');
    }
    const std::string n = std::to_string(token.size());
    if (!printable) return n + " bytes, not all printable ASCII";
    if (blank) return "text of " + n + " characters";
    if (digits) return "a malformed number of " + n + " characters";
    return "a word of " + n + " characters";
}

std::string unit_or_description(const std::string& token) {
    constexpr std::size_t kMaxUnitChars = 16;
    bool unit = !token.empty() && token.size() <= kMaxUnitChars;
    for (unsigned char c : token) unit = unit && c < 0x80 && (std::isalnum(c) || std::strchr("/^.*-", c) != nullptr);
    return unit ? "'" + token + "'" : describe_token(token);
}

}  // namespace ipmsm
