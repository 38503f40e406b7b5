#include "loom/InputFile.h"

#include <fmt/format.h>

#include <cerrno>
#include <cmath>
#include <cstdlib>
#include <fstream>

#include "loom/Error.h"
#include "loom/Graph.h"

namespace loom {

namespace fs = std::filesystem;

std::string readInputFile(const fs::path& path, const std::string& what, const std::string& expected,
                          uint64_t maxBytes) {
    const std::string name = path.string();
    std::error_code ec;
    const fs::file_status status = fs::status(path, ec);
    if (!fs::exists(status)) throwBadInput({}, what + " not found", expected, "check the path", name);
    if (fs::is_directory(status)) throwBadInput({}, "is a folder, not a " + what, expected, {}, name);
    if (!fs::is_regular_file(status))
        throwBadInput({}, "not a regular file (a pipe or a device)", expected, "give a file saved on disk", name);
    const uintmax_t size = fs::file_size(path, ec);
    if (ec) throwBadInput({}, "cannot read the " + what, "a readable file", "check its permissions", name);
    if (size > maxBytes)
        throwBadInput({}, fmt::format("the {} is {} MiB, more than a {} can be", what, size >> 20, what),
                      fmt::format("at most {} MiB", maxBytes >> 20), "check that this is the right file", name);
    std::ifstream in(path, std::ios::binary);
    std::string bytes(size_t(size), '\0');
    if (!in || !in.read(bytes.data(), std::streamsize(size)))
        throwBadInput({}, "cannot read the " + what, "a readable file", "check its permissions", name);
    return bytes;
}

void checkJsonText(std::string_view text, const std::string& file, bool numbers) {
    const auto at = [&](size_t offset) {
        size_t line, column;
        lineColumn(std::string(text.substr(0, offset + 1)), offset, line, column);
        return fmt::format("line {}, column {}", line, column);
    };
    int depth = 0;
    for (size_t i = 0; i < text.size(); ++i) {
        const char c = text[i];
        if (c == '"') {  // a string: skip it, escapes included (an unterminated one is the parser's to report)
            for (++i; i < text.size() && text[i] != '"'; ++i)
                if (text[i] == '\\') ++i;
        } else if (c == '[' || c == '{') {
            if (++depth > kMaxJsonDepth)
                throwBadInput(at(i), fmt::format("arrays and objects nested more than {} deep", kMaxJsonDepth),
                              fmt::format("at most {} levels", kMaxJsonDepth), {}, file);
        } else if (c == ']' || c == '}') {
            --depth;
        } else if (numbers && (c == '-' || (c >= '0' && c <= '9'))) {
            size_t end = i + 1;
            while (end < text.size() && (std::isdigit(static_cast<unsigned char>(text[end])) || text[end] == '.' ||
                                         text[end] == 'e' || text[end] == 'E' || text[end] == '+' || text[end] == '-'))
                ++end;
            const std::string number(text.substr(i, end - i));
            errno = 0;
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
