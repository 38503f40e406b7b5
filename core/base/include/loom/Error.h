#pragma once
// The one error type for user-facing failures.
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

namespace loom {

enum class ErrorKind {
    BadInput,  ///< the user's graph, scene, arguments or files are wrong (exit code 2)
    Runtime,   ///< the input was fine but running it failed (exit code 1)
};

/// A failure the user can act on: where it happened (file, JSON path or
/// Pass.channel), what went wrong, what was expected, and a suggestion.
class Error : public std::runtime_error {
public:
    struct Info {
        ErrorKind kind = ErrorKind::BadInput;
        std::string file;        ///< file the problem is in, if any
        std::string where;       ///< JSON path ("/passes/2/type") or "Pass.channel"
        std::string what;        ///< what went wrong
        std::string expected;    ///< what was expected instead
        std::string suggestion;  ///< what the user could do
    };

    explicit Error(Info info);

    const Info& info() const { return mInfo; }
    ErrorKind kind() const { return mInfo.kind; }
    /// Process exit code for this error: 2 for bad input, 1 for runtime.
    int exitCode() const { return mInfo.kind == ErrorKind::BadInput ? 2 : 1; }

    /// Returns a copy with the file set when it was not set yet.
    Error withFile(const std::string& file) const;

private:
    static std::string format(const Info& info);
    Info mInfo;
};

/// Shorthand for a bad-input error.
[[noreturn]] void throwBadInput(std::string where, std::string what, std::string expected = {},
                                std::string suggestion = {}, std::string file = {});

/// Closest candidate by edit distance, or empty when none is close enough.
std::string closestMatch(std::string_view name, const std::vector<std::string>& candidates);

/// "did you mean 'x'?" or, when none is close, a list of the candidates under `listLabel`; with an empty label (the
/// error's `expected` lists them already) a note that none is close instead.
std::string didYouMean(std::string_view name, const std::vector<std::string>& candidates,
                       std::string_view listLabel = "known");

/// Text from files (a JSON parser's "last read" bytes, a header line, a decoder's reason) as a terminal shows it:
/// well-formed UTF-8, line breaks and tabs kept, every other byte written as \xNN (invisible formatting characters
/// such as U+202E, the right-to-left override, included). Error messages pass through it.
std::string printable(std::string_view s);

/// A letter or '_', then letters, digits and '_': the names of parameters and fields, which appear in
/// "Pass.field" references, globs and file names.
bool isPlainName(std::string_view s);

/// Joins strings with a separator.
std::string join(const std::vector<std::string>& items, std::string_view sep = ", ");

}  // namespace loom
