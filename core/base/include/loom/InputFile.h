#pragma once
// Reading the files a user hands to Loom (graphs, scenes, scripts) without trusting them: what is not a regular file
// (a FIFO or a device, which may block or never end) or is larger than it can sensibly be, and JSON that the parser
// takes but its consumers cannot (nesting deep enough to exhaust the stack, numbers beyond double range), are bad
// input.
#include <cstdint>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <string>
#include <string_view>

namespace loom {

/// The deepest nesting of arrays and objects Loom's JSON inputs may have (graphs and glTF need fewer than 20).
inline constexpr int kMaxJsonDepth = 200;

/// Why the file cannot be read as an input, or empty when it can: "does not exist", "is a folder", "is not a regular
/// file (a pipe or a device)", "cannot be read (check its permissions)", "is larger than N MiB".
std::string inputFileProblem(const std::filesystem::path& path, uint64_t maxBytes);

/// The whole of the file as bytes (readFileBytes) once inputFileProblem finds none: otherwise bad input (exit 2)
/// naming the problem; `what` names the file in the message ("graph file"), `expected` says what it should be.
std::string readInputFile(const std::filesystem::path& path, const std::string& what, const std::string& expected,
                          uint64_t maxBytes);

/// Bad input, with line and column, for JSON text whose arrays and objects nest deeper than kMaxJsonDepth, that
/// gives a key twice in one object (parsers keep one value silently), that holds a NUL byte with text after it
/// (parsers stop there silently), or (with `numbers`) that holds a number beyond the range of a double (1e400).
/// Anything else is left to the parser. Keys are compared as written: "a" and "\u0061" count as two.
void checkJsonText(std::string_view text, const std::string& file, bool numbers = true);

/// A JSON value as error messages quote it: its text, cut to at most maxChars characters with "..." after.
std::string jsonExcerpt(const nlohmann::json& value, size_t maxChars = 60);

}  // namespace loom
