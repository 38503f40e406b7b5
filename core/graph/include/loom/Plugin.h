#pragma once
// Render-pass plugins: shared libraries that register pass types, loaded on
// demand from the build's plugin folder and LOOM_PLUGIN_PATH.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "loom/RenderPass.h"

/// Bumped whenever RenderPass, PassContext or the registrar change layout (4: ParamDecl::role; 5: FieldDesc::role;
/// 6: RenderPass::skippedWork; 7: PassContext::inputParamsChanged; 8: CompileInfo::readOutputs; 9: devices:
/// RenderPass::runsOn, PassContext::device, Texture residence; 10: FieldDesc::inPlace; 12: RenderPass::naturalSize).
#define LOOM_PLUGIN_ABI_VERSION 12

#if defined(_WIN32)
#define LOOM_PLUGIN_EXPORT extern "C" __declspec(dllexport)
#else
#define LOOM_PLUGIN_EXPORT extern "C" __attribute__((visibility("default")))
#endif

namespace loom {

using PassFactory = std::function<std::unique_ptr<RenderPass>()>;

struct PassTypeInfo {
    std::string type;
    std::string description;
    PassFactory factory;
    std::filesystem::path library;  ///< the plugin it came from (empty when built in)
};

/// Handed to a plugin's registration function.
class PluginRegistrar {
public:
    virtual ~PluginRegistrar() = default;
    virtual void registerPass(const std::string& type, const std::string& description, PassFactory factory) = 0;
    template <class T>
    void registerPass(const std::string& type, const std::string& description) {
        registerPass(type, description, [] { return std::make_unique<T>(); });
    }
};

/// Knows the plugin libraries and the pass types they provide.
///
/// Each plugin library `libloom_X.so` sits next to a manifest `libloom_X.json`
/// ({"library": "libloom_X.so", "types": [...]}) written by the build, so a
/// graph that names a type loads only the library that provides it. A
/// library without a manifest is loaded when a type cannot be found otherwise.
class PluginRegistry {
public:
    /// Search folders: `dirs`, then each entry of LOOM_PLUGIN_PATH
    /// (colon-separated) when useEnvironment.
    explicit PluginRegistry(std::vector<std::filesystem::path> dirs, bool useEnvironment = true);
    ~PluginRegistry();
    PluginRegistry(const PluginRegistry&) = delete;
    PluginRegistry& operator=(const PluginRegistry&) = delete;

    /// The default search folders: the plugin folder next to the running
    /// executable (../plugins, ../lib/loom/plugins) and the build's folder.
    static std::vector<std::filesystem::path> defaultDirs();

    /// Creates a pass of a type, loading its library when needed, and
    /// declares its parameters. Throws loom::Error: unknown type (lists the
    /// known ones with a did-you-mean), missing library, missing dependency
    /// (dlerror), ABI mismatch, duplicate type.
    std::unique_ptr<RenderPass> create(const std::string& type);
    /// Is the type known (registered or announced by a manifest)?
    bool knows(const std::string& type) const;
    /// Names of every type registered or announced by a manifest, sorted.
    std::vector<std::string> knownTypes() const;
    /// Loads every library found (for `loom passes`).
    void loadAll();
    /// Loads one library file. Throws loom::Error as create() does.
    void loadLibrary(const std::filesystem::path& file);
    const PassTypeInfo* typeInfo(const std::string& type) const;
    /// Registered types (after loading), sorted by name.
    std::vector<const PassTypeInfo*> registeredTypes() const;
    const std::vector<std::filesystem::path>& searchDirs() const { return mDirs; }

    /// Registers a type directly (tests, built-in passes).
    void registerPass(const std::string& type, const std::string& description, PassFactory factory,
                      const std::filesystem::path& library = {});

private:
    void scan();
    std::vector<std::filesystem::path> mDirs;
    std::map<std::string, PassTypeInfo> mTypes;                 // registered
    std::map<std::string, std::filesystem::path> mAnnounced;    // type -> library, from manifests
    std::map<std::string, std::vector<std::filesystem::path>> mAnnouncedAlso;  // type -> further libraries announcing it
    std::vector<std::filesystem::path> mUnannounced;            // libraries without a manifest
    std::vector<std::filesystem::path> mLibraries;              // every library found, in search order
    std::map<std::filesystem::path, void*> mHandles;            // loaded libraries
    bool mScanned = false;
};

}  // namespace loom

// Every plugin defines these two functions:
//   LOOM_PLUGIN_EXPORT uint32_t loomPluginAbiVersion() { return LOOM_PLUGIN_ABI_VERSION; }
//   LOOM_PLUGIN_EXPORT void loomRegisterPlugin(loom::PluginRegistrar& r) { r.registerPass<MyPass>("MyPass", "..."); }
// LOOM_DEFINE_PLUGIN does both.
#define LOOM_DEFINE_PLUGIN(registrarName)                                                      \
    LOOM_PLUGIN_EXPORT uint32_t loomPluginAbiVersion() { return LOOM_PLUGIN_ABI_VERSION; }      \
    LOOM_PLUGIN_EXPORT void loomRegisterPlugin(loom::PluginRegistrar& registrarName)
