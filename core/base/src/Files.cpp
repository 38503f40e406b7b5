#include "loom/Files.h"

#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <iterator>
#include <system_error>

#include "loom/Error.h"
#include "loom/PartialFiles.h"

namespace loom {

namespace fs = std::filesystem;

namespace {

[[noreturn]] void throwRuntime(const fs::path& file, std::string what, std::string suggestion = {}) {
    throw Error(Error::Info{ErrorKind::Runtime, file.string(), "", std::move(what), "", std::move(suggestion)});
}

/// The folder a file is written into must exist and be writable: otherwise it is the user's mistake (a wrong
/// --output path), not a runtime failure. `where`: the option that named the file, if any.
void checkOutputFolder(const fs::path& path, const std::string& where = {}) {
    fs::path folder = path.parent_path();
    if (folder.empty()) folder = ".";
    std::error_code ec;
    if (!fs::exists(folder, ec)) {
        throwBadInput(where, "folder does not exist: " + folder.string(), "an existing folder",
                      "create the folder first or choose another output path", path.string());
    }
    if (!fs::is_directory(folder, ec)) {
        throwBadInput(where, "not a folder: " + folder.string(), "an existing folder", "choose another output path",
                      path.string());
    }
    if (::access(folder.c_str(), W_OK) != 0) {
        throwBadInput(where, "cannot write into folder " + folder.string() + ": " + std::strerror(errno),
                      "a writable folder", "check the folder's permissions or choose another output path",
                      path.string());
    }
}

/// A file that exists but is not a regular one (a device, a pipe, a socket) is never replaced by an output.
void checkNotSpecial(const fs::path& path, const std::string& where) {
    std::error_code ec;
    const fs::file_status status = fs::symlink_status(path, ec);
    if (fs::exists(status) && !fs::is_regular_file(status) && !fs::is_directory(status) && !fs::is_symlink(status))
        throwBadInput(where, "the output path is not a regular file (a device or a pipe)", "a file name",
                      "choose another output path", path.string());
}

}  // namespace

// While it exists the temporary file is registered (PartialFiles.h), so a process ended by a signal removes it too.
void writeAtomically(const fs::path& path, const std::function<void(std::ofstream&, const std::string&)>& write) {
    checkOutputFolder(path);
    checkNotSpecial(path, {});
    static std::atomic<uint64_t> counter{0};
    // A hidden sibling ".<name>.<pid>.<n>.partial": never mistaken for an output, never a glob match.
    std::string name = ".";  // appended piece by piece: GCC 12 warns falsely (-Wrestrict) on "." + string
    name += path.filename().string();
    for (const std::string& part : {std::to_string(::getpid()), std::to_string(counter++), std::string("partial")})
        name += '.' + part;
    const std::string tmp = (path.parent_path() / name).string();
    auto removeTmp = [&] {
        std::error_code ignored;
        fs::remove(tmp, ignored);
    };
    PartialFile partial(tmp);  // unregistered when it dies: after the rename or the removal below
    try {
        std::ofstream out;
        errno = 0;
        out.open(tmp, std::ios::binary | std::ios::trunc);
        partial.created();
        if (!out) {
            int err = errno;
            std::string reason = err ? std::strerror(err) : "unknown error";
            if (err == EACCES || err == EPERM || err == EROFS) {
                throwBadInput("", "cannot write " + tmp + ": " + reason, "a writable folder",
                              "check the folder's permissions or choose another output path", path.string());
            }
            throwRuntime(path, "cannot create " + tmp + ": " + reason, "check free disk space and the output path");
        }
        write(out, tmp);
        out.close();
        if (!out) {
            throwRuntime(path, "writing " + tmp + " failed: " + (errno ? std::strerror(errno) : "unknown error"),
                         "check free disk space");
        }
        std::error_code ec;
        fs::rename(tmp, path, ec);
        if (ec) {
            throwRuntime(path, "cannot rename " + tmp + " to " + path.string() + ": " + ec.message(),
                         "check that the output path is not a folder and is writable");
        }
    } catch (const Error&) {
        awaitEndIfEnding();  // the failure may be the removal of the file by a signal handler
        removeTmp();
        throw;
    } catch (const std::exception& e) {
        awaitEndIfEnding();
        removeTmp();
        throwRuntime(path, std::string("writing failed: ") + e.what(), "check free disk space and the output path");
    } catch (...) {
        awaitEndIfEnding();
        removeTmp();
        throw;
    }
}

std::string readFileBytes(const fs::path& path) {
    std::ifstream in(path, std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    if (in.bad()) throwRuntime(path, "cannot read the file");
    return bytes;
}

void checkOutputFile(const fs::path& path, const std::string& where, const std::vector<fs::path>& inputs) {
    if (path.empty()) throwBadInput(where, "the output path is empty", "a file name");
    checkOutputFolder(path, where);
    std::error_code ec;
    if (fs::is_directory(path, ec) || path.filename().empty())
        throwBadInput(where, "the output path is a folder", "a file name", "name a file inside the folder",
                      path.string());
    checkNotSpecial(path, where);
    for (const fs::path& input : inputs)
        if (!input.empty() && fs::equivalent(path, input, ec))
            throwBadInput(where, "the output would overwrite the input " + input.string(), "a file name of its own",
                          "choose another output path", path.string());
}

void writeFileAtomic(const fs::path& path, const std::string& bytes) {
    writeAtomically(
        path, [&](std::ofstream& out, const std::string&) { out.write(bytes.data(), std::streamsize(bytes.size())); });
}

void lineColumn(std::string_view text, size_t offset, size_t& line, size_t& column) {
    line = 1;
    column = 1;
    for (size_t i = 0; i < offset && i < text.size(); ++i) {
        if (text[i] == '\n') {
            ++line;
            column = 1;
        } else {
            ++column;
        }
    }
}

}  // namespace loom
