// Reading a data file (a flux map) whole, with bounds: the file must be a regular file (a FIFO,
// a device or a directory is refused at once, without blocking on it) no larger than a limit,
// and its path is UTF-8 on every platform (on Windows converted to the wide API, so that a
// non-ASCII path does not go through the ANSI code page).
#pragma once

#include <cstddef>
#include <stdexcept>
#include <string>

namespace ipmsm {

struct MapFileError : std::runtime_error {
    using std::runtime_error::runtime_error;
};

// The largest data file read: 64 MiB, some 100 times a 512 x 512 flux map in full precision.
inline constexpr std::size_t kMaxMapFileBytes = std::size_t{64} << 20;

// The bytes of the regular file at utf8_path. Throws MapFileError ("cannot open file (...)",
// "not a regular file (a FIFO / a device / a directory)", "larger than N bytes") without
// allocating more than max_bytes.
std::string read_map_file(const std::string& utf8_path, std::size_t max_bytes = kMaxMapFileBytes);

// At most max_chars characters of text, as valid UTF-8 for a log: bytes that are not valid UTF-8
// become \xNN, control characters \n, \r, \t or \xNN; a longer text is cut with
// "... (N bytes in all)". Used for what the user named (a path, a parameter), never for a file's
// content: any file can be named as a map (describe_token).
std::string quoted_excerpt(const std::string& text, std::size_t max_chars = 200);

// What kind of token a piece of a file is, without its content ("a word of 6 characters", "12
// bytes, not all printable ASCII", "empty"): a message says what was expected and where, and
// never echoes a file into a log (a map parameter may name any file the process can read).
std::string describe_token(const std::string& token);

// token if it has the shape of a unit ("mOhm", "W/Hz^2": at most 16 ASCII letters, digits and
// / ^ . * -), else describe_token(token).
std::string unit_or_description(const std::string& token);

}  // namespace ipmsm
