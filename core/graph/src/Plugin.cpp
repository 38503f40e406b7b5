#include "loom/Plugin.h"

#include <dlfcn.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <fstream>
#include <set>
#include <sstream>

#include <nlohmann/json.hpp>
#include <spdlog/spdlog.h>

#include "loom/Error.h"

namespace fs = std::filesystem;

namespace loom {

namespace {

[[noreturn]] void pluginError(const fs::path& lib, std::string what, std::string expected, std::string suggestion,
                              ErrorKind kind = ErrorKind::BadInput) {
    throw Error(Error::Info{kind, lib.string(), {}, std::move(what), std::move(expected), std::move(suggestion)});
}

bool isPluginLibrary(const fs::path& p) {
    auto name = p.filename().string();
    return p.extension() == ".so" && name.rfind("libloom_", 0) == 0;
}

fs::path executableDir() {
    std::error_code ec;
    fs::path exe = fs::read_symlink("/proc/self/exe", ec);
    return ec ? fs::path() : exe.parent_path();
}

class Registrar final : public PluginRegistrar {
public:
    Registrar(PluginRegistry& reg, fs::path lib) : mReg(reg), mLib(std::move(lib)) {}
    void registerPass(const std::string& type, const std::string& description, PassFactory factory) override {
        mReg.registerPass(type, description, std::move(factory), mLib);
    }

private:
    PluginRegistry& mReg;
    fs::path mLib;
};

}  // namespace

PluginRegistry::PluginRegistry(std::vector<fs::path> dirs, bool useEnvironment) : mDirs(std::move(dirs)) {
    if (useEnvironment) {
        if (const char* env = std::getenv("LOOM_PLUGIN_PATH")) {
            std::stringstream ss(env);
            std::string item;
            while (std::getline(ss, item, ':'))
                if (!item.empty()) mDirs.emplace_back(item);
        }
    }
}

PluginRegistry::~PluginRegistry() {
    // Pass types hold factories that live in the libraries: drop them first.
    // Libraries stay loaded until process exit (passes created from them may
    // still be alive, and unloading C++ code with static state is fragile).
    mTypes.clear();
}

std::vector<fs::path> PluginRegistry::defaultDirs() {
    std::vector<fs::path> dirs;
    fs::path exeDir = executableDir();
    if (!exeDir.empty()) {
        dirs.push_back(exeDir / ".." / "plugins");
        dirs.push_back(exeDir / ".." / "lib" / "loom" / "plugins");
    }
    dirs.emplace_back(LOOM_BUILD_PLUGIN_DIR);
    return dirs;
}

void PluginRegistry::scan() {
    if (mScanned) return;
    mScanned = true;
    std::set<fs::path> seen;
    for (const auto& dir : mDirs) {
        std::error_code ec;
        if (!fs::is_directory(dir, ec)) continue;
        std::vector<fs::path> entries;
        for (const auto& e : fs::directory_iterator(dir, ec)) entries.push_back(e.path());
        std::sort(entries.begin(), entries.end());
        for (const auto& p : entries) {
            fs::path canonical = fs::weakly_canonical(p, ec);
            if (p.extension() == ".json" && p.filename().string().rfind("libloom_", 0) == 0) {
                std::ifstream in(p);
                auto manifest = nlohmann::json::parse(in, nullptr, false);
                bool valid = manifest.is_object() && manifest.contains("library") && manifest["library"].is_string() &&
                             manifest.contains("types") && manifest["types"].is_array();
                if (valid)
                    for (const auto& t : manifest["types"]) valid = valid && t.is_string();
                if (!valid) {
                    spdlog::warn("{}: not a valid plugin manifest; ignored", p.string());
                    continue;
                }
                fs::path lib = fs::weakly_canonical(dir / manifest["library"].get<std::string>(), ec);
                for (const auto& t : manifest["types"]) {
                    auto type = t.get<std::string>();
                    if (!mAnnounced.count(type))
                        mAnnounced[type] = lib;
                    else if (mAnnounced[type] != lib)
                        mAnnouncedAlso[type].push_back(lib);
                }
                if (seen.insert(lib).second) mLibraries.push_back(lib);
            }
        }
        for (const auto& p : entries) {
            fs::path canonical = fs::weakly_canonical(p, ec);
            if (isPluginLibrary(p) && !seen.count(canonical)) {
                mUnannounced.push_back(canonical);
                mLibraries.push_back(canonical);
                seen.insert(canonical);
            }
        }
    }
}

void PluginRegistry::registerPass(const std::string& type, const std::string& description, PassFactory factory,
                                  const fs::path& library) {
    if (auto it = mTypes.find(type); it != mTypes.end()) {
        std::string first = it->second.library.empty() ? "built in" : it->second.library.string();
        std::string second = library.empty() ? "built in" : library.string();
        pluginError(library, "pass type '" + type + "' is registered twice: by " + first + " and by " + second,
                    "each pass type registered by exactly one plugin",
                    "remove one of the libraries from the plugin path or rename the type");
    }
    mTypes[type] = PassTypeInfo{type, description, std::move(factory), library};
}

void PluginRegistry::loadLibrary(const fs::path& file) {
    std::error_code ec;
    fs::path lib = fs::weakly_canonical(file, ec);
    if (mHandles.count(lib)) return;
    if (!fs::exists(lib, ec))
        pluginError(lib, "plugin library not found", "the library named by its manifest",
                    "rebuild Loom (the library may have been deleted) or fix LOOM_PLUGIN_PATH");
    dlerror();
    void* handle = dlopen(lib.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (!handle) {
        const char* err = dlerror();
        std::string msg = err ? err : "unknown dlopen error";
        std::string hint = "run `ldd " + lib.string() + "` to see which dependency is missing";
        if (msg.find("cannot open shared object file") != std::string::npos &&
            msg.find(lib.filename().string()) == std::string::npos)
            hint = "a library this plugin depends on is missing; install it or add its folder to LD_LIBRARY_PATH (" +
                   hint + ")";
        pluginError(lib, "cannot load plugin library: " + msg, "a loadable shared library", hint);
    }
    using AbiFn = uint32_t (*)();
    using RegisterFn = void (*)(PluginRegistrar&);
    auto abi = reinterpret_cast<AbiFn>(dlsym(handle, "loomPluginAbiVersion"));
    auto reg = reinterpret_cast<RegisterFn>(dlsym(handle, "loomRegisterPlugin"));
    if (!abi || !reg) {
        dlclose(handle);
        pluginError(lib, "not a Loom plugin: loomPluginAbiVersion or loomRegisterPlugin is missing",
                    "a library built with LOOM_DEFINE_PLUGIN", "remove it from the plugin folder");
    }
    uint32_t version = abi();
    if (version != LOOM_PLUGIN_ABI_VERSION) {
        dlclose(handle);
        pluginError(lib, fmt::format("plugin ABI version {} does not match Loom's {}", version,
                                     LOOM_PLUGIN_ABI_VERSION),
                    fmt::format("ABI version {}", LOOM_PLUGIN_ABI_VERSION),
                    "rebuild the plugin against this version of Loom");
    }
    mHandles[lib] = handle;
    Registrar r(*this, lib);
    // A registration that fails names the library, whatever it threw.
    try {
        reg(r);
    } catch (const Error& e) {
        if (!e.info().file.empty()) throw;
        throw e.withFile(lib.string());
    } catch (const std::exception& e) {
        pluginError(lib, std::string("registering the plugin failed: ") + e.what(), "a registration that succeeds",
                    "fix or remove the plugin", ErrorKind::Runtime);
    } catch (...) {
        pluginError(lib, "registering the plugin failed with an exception that is not a std::exception",
                    "a registration that succeeds", "fix or remove the plugin", ErrorKind::Runtime);
    }
    spdlog::debug("loaded plugin {}", lib.string());
}

bool PluginRegistry::knows(const std::string& type) const {
    const_cast<PluginRegistry*>(this)->scan();
    return mTypes.count(type) || mAnnounced.count(type);
}

std::vector<std::string> PluginRegistry::knownTypes() const {
    const_cast<PluginRegistry*>(this)->scan();
    std::set<std::string> all;
    for (const auto& [t, _] : mTypes) all.insert(t);
    for (const auto& [t, _] : mAnnounced) all.insert(t);
    return {all.begin(), all.end()};
}

void PluginRegistry::loadAll() {
    scan();
    // Every library found, in search order: also one whose manifest types are all announced by an earlier
    // library, so that a duplicate type is reported instead of silently hidden.
    for (const auto& lib : mLibraries) loadLibrary(lib);
}

std::unique_ptr<RenderPass> PluginRegistry::create(const std::string& type) {
    scan();
    // A type two plugins announce: loading them all reports the duplicate (registerPass), rather than silently
    // using the first one found.
    if (auto also = mAnnouncedAlso.find(type); also != mAnnouncedAlso.end()) {
        if (auto first = mAnnounced.find(type); first != mAnnounced.end()) loadLibrary(first->second);
        for (const auto& lib : also->second) loadLibrary(lib);
    }
    if (!mTypes.count(type)) {
        if (auto it = mAnnounced.find(type); it != mAnnounced.end()) {
            loadLibrary(it->second);
            if (!mTypes.count(type))
                pluginError(it->second, "the plugin's manifest announces pass type '" + type +
                                            "' but the library did not register it",
                            "the manifest and the library to agree", "rebuild the plugin");
        } else {
            for (const auto& lib : mUnannounced) {
                loadLibrary(lib);
                if (mTypes.count(type)) break;
            }
        }
    }
    auto it = mTypes.find(type);
    if (it == mTypes.end()) {
        auto known = knownTypes();
        std::vector<std::string> dirs;
        for (const auto& d : mDirs) dirs.push_back(d.string());
        std::string hint = didYouMean(type, known, "known types");
        if (closestMatch(type, known).empty())
            hint = "no plugin provides it; plugins are searched in " + join(dirs) + " and LOOM_PLUGIN_PATH";
        throwBadInput({}, "unknown pass type '" + type + "'", "one of: " + join(known), hint);
    }
    auto pass = it->second.factory();
    if (!pass)
        pluginError(it->second.library, "the factory of pass type '" + type + "' returned no pass",
                    "a factory that returns a new pass", "fix the plugin's LOOM_DEFINE_PLUGIN registration",
                    ErrorKind::Runtime);
    try {
        pass->declareParams(pass->params());
    } catch (const Error&) {
        throw;
    } catch (const std::exception& e) {
        pluginError(it->second.library, "pass type '" + type + "' failed to declare its parameters: " + e.what(),
                    "declareParams() that does not throw", "fix the pass's declareParams()", ErrorKind::Runtime);
    }
    if (const std::string problem = pass->params().declarationProblem(); !problem.empty())
        pluginError(it->second.library, "pass type '" + type + "': " + problem, "valid parameter declarations",
                    "fix the pass's declareParams()", ErrorKind::Runtime);
    return pass;
}

const PassTypeInfo* PluginRegistry::typeInfo(const std::string& type) const {
    auto it = mTypes.find(type);
    return it == mTypes.end() ? nullptr : &it->second;
}

std::vector<const PassTypeInfo*> PluginRegistry::registeredTypes() const {
    std::vector<const PassTypeInfo*> out;
    for (const auto& [_, info] : mTypes) out.push_back(&info);
    return out;
}

}  // namespace loom
