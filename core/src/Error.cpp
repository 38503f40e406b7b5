#include "loom/Error.h"

#include <algorithm>
#include <sstream>

namespace loom {

Error::Error(Info info) : std::runtime_error(format(info)), mInfo(std::move(info)) {}

std::string Error::format(const Info& info) {
    std::ostringstream s;
    if (!info.file.empty()) s << info.file << ": ";
    if (!info.where.empty()) s << info.where << ": ";
    s << info.what;
    if (!info.expected.empty()) s << "\n  expected: " << info.expected;
    if (!info.suggestion.empty()) s << "\n  hint: " << info.suggestion;
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
    return std::string(listLabel) + ": " + join(candidates);
}

}  // namespace loom
