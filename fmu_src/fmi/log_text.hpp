// Text for a log: valid UTF-8 and bounded, whatever it echoes (a line of a file, a path in a
// Latin-1 or UTF-16 encoding, a 200 MB line). fmpy decodes log messages as UTF-8 and raises on
// invalid bytes, so the FMU's reason would be lost. FMI-free: the readers (machine/) use it too.
#pragma once

#include <cstddef>
#include <cstdio>
#include <string>

namespace fmi {

// The length of the valid UTF-8 sequence at s[i], or 0 (overlong forms, surrogates and code
// points above U+10FFFF are invalid).
inline std::size_t utf8_length(const std::string& s, std::size_t i) {
    const auto b = [&](std::size_t k) { return static_cast<unsigned char>(s[k]); };
    const unsigned c = b(i);
    if (c < 0x80) return 1;
    std::size_t n;
    unsigned lo = 0x80, hi = 0xBF;
    if (c >= 0xC2 && c <= 0xDF) {
        n = 2;
    } else if (c >= 0xE0 && c <= 0xEF) {
        n = 3;
        if (c == 0xE0) lo = 0xA0;
        if (c == 0xED) hi = 0x9F;
    } else if (c >= 0xF0 && c <= 0xF4) {
        n = 4;
        if (c == 0xF0) lo = 0x90;
        if (c == 0xF4) hi = 0x8F;
    } else {
        return 0;
    }
    if (i + n > s.size() || b(i + 1) < lo || b(i + 1) > hi) return 0;
    for (std::size_t k = 2; k < n; ++k)
        if (b(i + k) < 0x80 || b(i + k) > 0xBF) return 0;
    return n;
}

// At most max_chars characters of text as valid UTF-8: invalid bytes become \xNN; with
// escape_controls, control characters too (\n, \r, \t, \xNN: an echoed input stays on one line);
// without, only \n, \r and \t are kept as they are (NUL and the others always escaped).
// A longer text is cut and ends in "... (N bytes in all)".
inline std::string utf8_excerpt(const std::string& text, std::size_t max_chars, bool escape_controls = true) {
    std::string out;
    std::size_t chars = 0, i = 0;
    while (i < text.size() && chars < max_chars) {
        const std::size_t n = utf8_length(text, i);
        const unsigned char c = static_cast<unsigned char>(text[i]);
        const bool control = n == 1 && (c < 0x20 || c == 0x7F);
        const bool line_break = c == '\n' || c == '\r' || c == '\t';
        if (n > 0 && (!control || (!escape_controls && line_break))) {
            out.append(text, i, n);
        } else if (c == '\n') {
            out += "\\n";
        } else if (c == '\r') {
            out += "\\r";
        } else if (c == '\t') {
            out += "\\t";
        } else {
            char hex[8];
            std::snprintf(hex, sizeof hex, "\\x%02X", c);
            out += hex;
        }
        i += n == 0 ? 1 : n;
        ++chars;
    }
    if (i < text.size()) out += "... (" + std::to_string(text.size()) + " bytes in all)";
    return out;
}

// The longest log message: a few echoed inputs of some hundred characters each, and the context.
inline constexpr std::size_t kMaxLogChars = 4000;

}  // namespace fmi
