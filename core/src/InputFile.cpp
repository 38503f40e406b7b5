#include "loom/InputFile.h"

#include <fmt/format.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>

#include "loom/Error.h"
#include "loom/Graph.h"
#include "loom/ImageIO.h"

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
