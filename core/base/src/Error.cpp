#include "loom/Error.h"

#include <algorithm>
#include <cstdint>
#include <sstream>

namespace loom {

namespace {

/// Whether a code point is a C1 control or one of Unicode's invisible format characters (soft hyphen, zero-width
/// spaces and joiners, bidirectional overrides and isolates, the byte-order mark): text holding them is not shown
/// as it is (a right-to-left override makes "exr.evil" of "live.rxe").
bool hiddenCodePoint(uint32_t cp) {
    return (cp >= 0x80 && cp <= 0x9F) || cp == 0xAD || cp == 0x61C || cp == 0x180E || (cp >= 0x200B && cp <= 0x200F) ||
           (cp >= 0x202A && cp <= 0x202E) || (cp >= 0x2060 && cp <= 0x206F) || cp == 0xFEFF ||
           (cp >= 0xFFF9 && cp <= 0xFFFB);
}

/// The length of the well-formed UTF-8 sequence at s[i] (a printable, visible character), or 0.
size_t utf8Length(std::string_view s, size_t i) {
    const auto byte = [&](size_t k) { return static_cast<unsigned char>(s[k]); };
    const unsigned char b = byte(i);
    if (b >= 0x20 && b < 0x7f) return 1;
    const size_t n = b >= 0xc2 && b <= 0xdf ? 2 : b >= 0xe0 && b <= 0xef ? 3 : b >= 0xf0 && b <= 0xf4 ? 4 : 0;
    if (n == 0 || i + n > s.size()) return 0;
    for (size_t k = 1; k < n; ++k)
        if ((byte(i + k) & 0xc0) != 0x80) return 0;
    // Overlong forms, UTF-16 surrogates and code points past U+10FFFF.
    const unsigned char b1 = byte(i + 1);
    if ((b == 0xe0 && b1 < 0xa0) || (b == 0xed && b1 >= 0xa0) || (b == 0xf0 && b1 < 0x90) || (b == 0xf4 && b1 >= 0x90))
        return 0;
    uint32_t cp = b & (0x7F >> n);
    for (size_t k = 1; k < n; ++k) cp = (cp << 6) | (byte(i + k) & 0x3F);
    return hiddenCodePoint(cp) ? 0 : n;
}

}  // namespace

std::string printable(std::string_view s) {
    std::string out;
    out.reserve(s.size());
    for (size_t i = 0; i < s.size();) {
        if (s[i] == '\n' || s[i] == '\t') {
            out += s[i++];
            continue;
        }
        if (const size_t n = utf8Length(s, i)) {
            out.append(s, i, n);
            i += n;
            continue;
        }
        static const char kHex[] = "0123456789abcdef";
        const unsigned char b = static_cast<unsigned char>(s[i++]);
        out += "\\x";
        out += kHex[b >> 4];
        out += kHex[b & 15];
    }
    return out;
}

Error::Error(Info info) : std::runtime_error(format(info)), mInfo(std::move(info)) {}

std::string Error::format(const Info& info) {
    std::ostringstream s;
    if (!info.file.empty()) s << printable(info.file) << ": ";
    if (!info.where.empty()) s << printable(info.where) << ": ";
    s << printable(info.what);
    if (!info.expected.empty()) s << "\n  expected: " << printable(info.expected);
    if (!info.suggestion.empty()) s << "\n  hint: " << printable(info.suggestion);
    return s.str();
}

Error Error::withFile(const std::string& file) const {
    Info copy = mInfo;
    if (copy.file.empty()) copy.file = file;
    return Error(std::move(copy));
}

void throwBadInput(std::string where, std::string what, std::string expected, std::string suggestion,
                   std::string file) {
    throw Error(Error::Info{ErrorKind::BadInput, std::move(file), std::move(where), std::move(what),
                            std::move(expected), std::move(suggestion)});
}

namespace {
size_t editDistance(std::string_view a, std::string_view b) {
    std::vector<size_t> prev(b.size() + 1), cur(b.size() + 1);
    for (size_t j = 0; j <= b.size(); ++j) prev[j] = j;
    for (size_t i = 1; i <= a.size(); ++i) {
        cur[0] = i;
        for (size_t j = 1; j <= b.size(); ++j) {
            bool same = std::tolower((unsigned char)a[i - 1]) == std::tolower((unsigned char)b[j - 1]);
            cur[j] = std::min({prev[j] + 1, cur[j - 1] + 1, prev[j - 1] + (same ? 0 : 1)});
        }
        std::swap(prev, cur);
    }
    return prev[b.size()];
}
}  // namespace

std::string closestMatch(std::string_view name, const std::vector<std::string>& candidates) {
    std::string best;
    size_t bestDist = SIZE_MAX;
    for (const auto& c : candidates) {
        size_t d = editDistance(name, c);
        if (d < bestDist) {
            bestDist = d;
            best = c;
        }
    }
    size_t limit = std::max<size_t>(2, name.size() / 3);
    return bestDist <= limit ? best : std::string();
}

bool isPlainName(std::string_view s) {
    const auto letter = [](char c) { return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || c == '_'; };
    return !s.empty() && letter(s[0]) &&
           std::all_of(s.begin(), s.end(), [&](char c) { return letter(c) || (c >= '0' && c <= '9'); });
}

std::string join(const std::vector<std::string>& items, std::string_view sep) {
    std::string out;
    for (size_t i = 0; i < items.size(); ++i) {
        if (i) out += sep;
        out += items[i];
    }
    return out;
}

std::string didYouMean(std::string_view name, const std::vector<std::string>& candidates,
                       std::string_view listLabel) {
    std::string best = closestMatch(name, candidates);
    if (!best.empty()) return "did you mean '" + best + "'?";
    if (candidates.empty()) return {};
    // The error's `expected` already lists them: say so rather than list them twice.
    if (listLabel.empty()) return "none of these is close to '" + printable(name) + "': check its spelling";
    return std::string(listLabel) + ": " + join(candidates);
}

}  // namespace loom
