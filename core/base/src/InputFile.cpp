#include "loom/InputFile.h"

#include <fmt/format.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <optional>
#include <set>
#include <string_view>
#include <vector>

#include "loom/Error.h"
#include "loom/Files.h"

namespace loom {

namespace fs = std::filesystem;

std::string inputFileProblem(const fs::path& path, uint64_t maxBytes) {
    std::error_code ec;
    const fs::file_status status = fs::status(path, ec);
    if (!fs::exists(status)) return "does not exist";
    if (fs::is_directory(status)) return "is a folder";
    if (!fs::is_regular_file(status)) return "is not a regular file (a pipe or a device)";
    const uintmax_t size = fs::file_size(path, ec);
    if (ec || ::access(path.c_str(), R_OK) != 0) return "cannot be read (check its permissions)";
    if (size > maxBytes) return fmt::format("is larger than {} MiB", maxBytes >> 20);
    return {};
}

std::string readInputFile(const fs::path& path, const std::string& what, const std::string& expected,
                          uint64_t maxBytes) {
    const std::string name = path.string();
    if (const std::string problem = inputFileProblem(path, maxBytes); !problem.empty())
        throwBadInput({}, "the " + what + " " + problem, expected,
                      problem == "does not exist" ? "check the path" : "give a file saved on disk", name);
    return readFileBytes(path);
}

void checkJsonText(std::string_view text, const std::string& file, bool numbers) {
    const auto at = [&](size_t offset) {
        size_t line, column;
        lineColumn(text, offset, line, column);
        return fmt::format("line {}, column {}", line, column);
    };
    // The keys of each open object (an array holds none): a key given twice would silently keep the last value.
    std::vector<std::optional<std::set<std::string_view>>> open;
    for (size_t i = 0; i < text.size(); ++i) {
        const char c = text[i];
        if (c == '"') {  // a string: skip it, escapes included (an unterminated one is the parser's to report)
            const size_t start = i + 1;
            for (++i; i < text.size() && text[i] != '"'; ++i)
                if (text[i] == '\\') ++i;
            if (open.empty() || !open.back() || i >= text.size()) continue;
            size_t next = i + 1;
            while (next < text.size() && std::isspace(static_cast<unsigned char>(text[next]))) ++next;
            if (next >= text.size() || text[next] != ':') continue;
            const std::string_view key = text.substr(start, i - start);
            if (!open.back()->insert(key).second)
                throwBadInput(at(start - 1), "the key \"" + printable(key.substr(0, 60)) + "\" appears twice in one object",
                              "each key once per object", "remove one of them: only one value can count", file);
        } else if (c == '[' || c == '{') {
            if (open.size() >= size_t(kMaxJsonDepth))
                throwBadInput(at(i), fmt::format("arrays and objects nested more than {} deep", kMaxJsonDepth),
                              fmt::format("at most {} levels", kMaxJsonDepth), {}, file);
            open.push_back(c == '{' ? std::optional<std::set<std::string_view>>(std::in_place) : std::nullopt);
        } else if (c == ']' || c == '}') {
            if (!open.empty()) open.pop_back();
        } else if (c == '\0') {
            // Padding of NUL bytes at the very end is tolerated (some writers pad binary glTF's JSON chunk so);
            // anything after a NUL would be read by no parser, and is an error rather than silently ignored.
            const bool padding = text.find_first_not_of(std::string_view("\0 \t\r\n", 5), i) == std::string_view::npos;
            if (!padding)
                throwBadInput(at(i), "a NUL byte inside the JSON text, with more text after it",
                              "JSON text without NUL bytes", "the file is damaged or not JSON", file);
            return;
        } else if (numbers && (c == '-' || (c >= '0' && c <= '9'))) {
            size_t end = i + 1;
            while (end < text.size() && (std::isdigit(static_cast<unsigned char>(text[end])) || text[end] == '.' ||
                                         text[end] == 'e' || text[end] == 'E' || text[end] == '+' || text[end] == '-'))
                ++end;
            const std::string number(text.substr(i, end - i));
            const double v = std::strtod(number.c_str(), nullptr);
            if (std::isinf(v))
                throwBadInput(at(i), "the number " + printable(number.substr(0, 40)) + " is too large",
                              "numbers within ±1.8e308 (and within the range each value allows)", {}, file);
            i = end - 1;
        }
    }
}

std::string jsonExcerpt(const nlohmann::json& value, size_t maxChars) {
    // Dumping is recursive, but checkJsonText bounds the depth of what the inputs hold.
    std::string text = value.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace);
    if (text.size() > maxChars) text = text.substr(0, maxChars) + "...";
    return text;
}

}  // namespace loom
