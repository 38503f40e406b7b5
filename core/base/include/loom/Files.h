#pragma once
// Files Loom writes and the text positions it reports. Every output is written atomically: a temporary file in
// the same folder, registered with PartialFiles.h while it exists, then a rename, so a reader never sees a
// half-written file, and a process ended by a signal leaves none behind.
#include <cstddef>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace loom {

/// Runs `write(out, tmpPath)` on a temporary file next to `path`, then renames it over `path`. The folder must
/// exist and be writable (bad input otherwise). On any failure the temporary file is removed and the error is
/// rethrown as a loom::Error (Runtime for I/O failures, naming the path).
void writeAtomically(const std::filesystem::path& path,
                     const std::function<void(std::ofstream& out, const std::string& tmpPath)>& write);

/// Writes bytes to a file atomically (writeAtomically). Throws loom::Error.
void writeFileAtomic(const std::filesystem::path& path, const std::string& bytes);

/// The whole file's bytes. Throws loom::Error (Runtime) when reading fails.
std::string readFileBytes(const std::filesystem::path& path);

/// Checks that a file can be written at `path`: its folder exists and is writable (as writeAtomically checks
/// first), and the path is not a folder. Throws loom::Error (BadInput, at `where`: the option that named the file)
/// otherwise, so a command can check its output files before it spends time on their contents. An empty path, and
/// a path that is one of `inputs` (the command's input files), are bad input too.
void checkOutputFile(const std::filesystem::path& path, const std::string& where = {},
                     const std::vector<std::filesystem::path>& inputs = {});

/// 1-based line and column of a byte offset in text, for error messages.
void lineColumn(std::string_view text, size_t offset, size_t& line, size_t& column);

}  // namespace loom
