// The plugin registry: manifests, on-demand loading, LOOM_PLUGIN_PATH, and every way loading a plugin can fail.
// Loaded libraries stay loaded for the process lifetime and a registry registers each type once, so every test
// uses its own PluginRegistry.
#include <gtest/gtest.h>

#include "TestUtil.h"
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <nlohmann/json.hpp>
#include <optional>
#include <string>
#include <vector>

#include "loom/Error.h"
#include "loom/Plugin.h"
#include "loom/Reflection.h"

using namespace loom;
namespace fs = std::filesystem;

namespace {

const std::vector<std::string> kTestTypes = {"Add",           "Blur",    "Constant", "FrameCounter", "NoOp",
                                             "OptionalInput", "Pattern", "Probe",    "ToSrgb8"};

fs::path pluginDir() {
    return LOOM_TEST_PLUGIN_DIR;
}
fs::path badDir(const char* sub) {
    return fs::path(LOOM_TEST_BAD_PLUGIN_DIR) / sub;
}
fs::path testPassesLib() {
    return fs::weakly_canonical(pluginDir() / "libloom_testpasses.so");
}

bool contains(const std::string& haystack, const std::string& needle) {
    return haystack.find(needle) != std::string::npos;
}

bool hasType(const std::vector<std::string>& types, const std::string& t) {
    return std::find(types.begin(), types.end(), t) != types.end();
}

using test::expectError;

/// Sets an environment variable for one scope and restores the previous value.
class ScopedEnv {
public:
    ScopedEnv(const char* name, const std::string& value) : mName(name) {
        if (const char* old = std::getenv(name)) mOld = old;
        ::setenv(name, value.c_str(), 1);
    }
    ~ScopedEnv() {
        if (mOld)
            ::setenv(mName.c_str(), mOld->c_str(), 1);
        else
            ::unsetenv(mName.c_str());
    }

private:
    std::string mName;
    std::optional<std::string> mOld;
};

class PluginFiles : public test::TempDirTest {};

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Discovery and creation

TEST(Plugins, ManifestAnnouncesTypesBeforeLoading) {
    PluginRegistry reg({pluginDir()}, /*useEnvironment=*/false);
    ASSERT_EQ(reg.searchDirs().size(), 1u);
    auto known = reg.knownTypes();
    for (const auto& t : kTestTypes) EXPECT_TRUE(hasType(known, t)) << t;
    EXPECT_TRUE(std::is_sorted(known.begin(), known.end()));
    EXPECT_TRUE(reg.knows("Blur"));
    EXPECT_FALSE(reg.knows("Blr"));
    // Nothing is loaded yet: the types are only announced.
    EXPECT_TRUE(reg.registeredTypes().empty());
    EXPECT_EQ(reg.typeInfo("Blur"), nullptr);
}

TEST(Plugins, CreateLoadsTheLibraryAndDeclaresParams) {
    PluginRegistry reg({pluginDir()}, false);
    auto blur = reg.create("Blur");
    ASSERT_NE(blur, nullptr);
    const ParamDecl* radius = blur->params().find("radius");
    ASSERT_NE(radius, nullptr);
    EXPECT_EQ(radius->type, ParamType::Int);
    EXPECT_EQ(blur->params().get("radius"), 2);
    EXPECT_NE(blur->params().find("readScratchFirst"), nullptr);
    EXPECT_EQ(blur->params().decls().size(), 2u);

    Reflection r;
    blur->reflect(r, CompileInfo{});
    ASSERT_NE(r.find("src"), nullptr);
    EXPECT_EQ(r.find("src")->kind, FieldKind::Input);
    ASSERT_NE(r.find("tmp"), nullptr);
    EXPECT_EQ(r.find("tmp")->kind, FieldKind::Internal);

    // Loading the library registered all its types, with the library recorded.
    const PassTypeInfo* info = reg.typeInfo("Blur");
    ASSERT_NE(info, nullptr);
    EXPECT_EQ(info->type, "Blur");
    EXPECT_FALSE(info->description.empty());
    EXPECT_EQ(info->library.string(), testPassesLib().string());
    ASSERT_NE(reg.typeInfo("Constant"), nullptr);
    EXPECT_EQ(reg.typeInfo("Constant")->library.string(), testPassesLib().string());

    // Each create() makes a new pass with its own parameters.
    auto blur2 = reg.create("Blur");
    ASSERT_NE(blur2, nullptr);
    EXPECT_NE(blur.get(), blur2.get());
    blur->params().set("radius", 9, "Blur.radius");
    EXPECT_EQ(blur2->params().get("radius"), 2);

    auto constant = reg.create("Constant");
    ASSERT_NE(constant, nullptr);
    EXPECT_NE(constant->params().find("color"), nullptr);
}

TEST(Plugins, PassOutlivesItsRegistry) {
    std::unique_ptr<RenderPass> pass;
    {
        PluginRegistry reg({pluginDir()}, false);
        pass = reg.create("Pattern");
    }
    ASSERT_NE(pass, nullptr);
    Reflection r;
    pass->reflect(r, CompileInfo{});
    EXPECT_NE(r.find("dst"), nullptr);
    EXPECT_EQ(pass->params().get("frequency"), 12.f);
}

TEST(Plugins, LoadAllRegistersEveryType) {
    PluginRegistry reg({pluginDir()}, false);
    reg.loadAll();
    auto registered = reg.registeredTypes();
    std::vector<std::string> names;
    for (const auto* info : registered) {
        ASSERT_NE(info, nullptr);
        names.push_back(info->type);
    }
    EXPECT_TRUE(std::is_sorted(names.begin(), names.end()));
    for (const auto& t : kTestTypes) {
        EXPECT_TRUE(hasType(names, t)) << t;
        const PassTypeInfo* info = reg.typeInfo(t);
        ASSERT_NE(info, nullptr) << t;
        EXPECT_EQ(info->library.string(), testPassesLib().string()) << t;
        EXPECT_TRUE(info->factory != nullptr) << t;
    }
    // Loading again is a no-op, not a duplicate registration.
    EXPECT_NO_THROW(reg.loadAll());
    EXPECT_NO_THROW(reg.loadLibrary(pluginDir() / "libloom_testpasses.so"));
    EXPECT_EQ(reg.registeredTypes().size(), registered.size());
}

TEST(Plugins, DirectRegistration) {
    PluginRegistry reg({}, false);
    EXPECT_TRUE(reg.knownTypes().empty());
    reg.registerPass("Builtin", "built in", [] { return std::unique_ptr<RenderPass>(); });
    EXPECT_TRUE(reg.knows("Builtin"));
    ASSERT_NE(reg.typeInfo("Builtin"), nullptr);
    EXPECT_TRUE(reg.typeInfo("Builtin")->library.empty());
    Error e = expectError([&] { reg.registerPass("Builtin", "again", [] { return std::unique_ptr<RenderPass>(); }); });
    EXPECT_TRUE(contains(e.what(), "registered twice")) << e.what();
    EXPECT_TRUE(contains(e.what(), "built in")) << e.what();
}

TEST(Plugins, DefaultDirsIncludeTheBuildPluginFolder) {
    auto dirs = PluginRegistry::defaultDirs();
    ASSERT_FALSE(dirs.empty());
    bool found = false;
    for (const auto& d : dirs) found |= fs::equivalent(d, pluginDir()) || d == pluginDir();
    EXPECT_TRUE(found);
}

// ---------------------------------------------------------------------------------------------------------------
// Unknown types

TEST(PluginErrors, UnknownTypeSuggestsNearMiss) {
    PluginRegistry reg({pluginDir()}, false);
    Error e = expectError([&] { (void)reg.create("Blr"); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_EQ(e.exitCode(), 2);
    EXPECT_TRUE(contains(e.what(), "unknown pass type 'Blr'")) << e.what();
    EXPECT_EQ(e.info().suggestion, "did you mean 'Blur'?");
    for (const auto& t : kTestTypes) EXPECT_TRUE(contains(e.info().expected, t)) << e.what();
}

TEST(PluginErrors, UnknownTypeFarFromAllListsTypesAndFolders) {
    PluginRegistry reg({pluginDir()}, false);
    Error e = expectError([&] { (void)reg.create("Zzzzzzzzzzzzzz"); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_FALSE(contains(e.what(), "did you mean")) << e.what();
    for (const auto& t : kTestTypes) EXPECT_TRUE(contains(e.info().expected, t)) << e.what();
    EXPECT_TRUE(contains(e.info().suggestion, pluginDir().string())) << e.what();
    EXPECT_TRUE(contains(e.info().suggestion, "LOOM_PLUGIN_PATH")) << e.what();
}

TEST(PluginErrors, NoPluginFolders) {
    PluginRegistry reg({"/nonexistent/loom/plugins"}, false);
    EXPECT_TRUE(reg.knownTypes().empty());
    Error e = expectError([&] { (void)reg.create("Blur"); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_TRUE(contains(e.what(), "unknown pass type 'Blur'")) << e.what();
}

// ---------------------------------------------------------------------------------------------------------------
// Broken plugins

TEST(PluginErrors, AbiMismatch) {
    PluginRegistry reg({badDir("abi")}, false);
    const fs::path lib = badDir("abi") / "libloom_bad_abi.so";
    const std::string theirs = std::to_string(LOOM_PLUGIN_ABI_VERSION + 1000);
    const std::string ours = std::to_string(LOOM_PLUGIN_ABI_VERSION);
    Error e = expectError([&] { reg.loadLibrary(lib); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_TRUE(contains(e.what(), "ABI")) << e.what();
    EXPECT_TRUE(contains(e.what(), "version " + theirs)) << e.what();
    EXPECT_TRUE(contains(e.what(), "Loom's " + ours)) << e.what();
    EXPECT_TRUE(contains(e.what(), "libloom_bad_abi.so")) << e.what();
    EXPECT_TRUE(contains(e.info().suggestion, "rebuild")) << e.what();

    // The failed library is not remembered as loaded: trying again (here through the manifest) fails again.
    EXPECT_TRUE(reg.knows("BadAbi"));
    Error again = expectError([&] { (void)reg.create("BadAbi"); });
    EXPECT_TRUE(contains(again.what(), "ABI")) << again.what();
    EXPECT_EQ(reg.typeInfo("BadAbi"), nullptr);
}

TEST(PluginErrors, RegistrationThatThrowsNamesTheLibrary) {
    PluginRegistry reg({badDir("throws")}, false);
    const fs::path lib = badDir("throws") / "libloom_throws_on_register.so";
    Error e = expectError([&] { reg.loadLibrary(lib); });
    EXPECT_TRUE(contains(e.what(), "libloom_throws_on_register.so")) << e.what();
    EXPECT_TRUE(contains(e.what(), "registering the plugin failed")) << e.what();
    Error viaType = expectError([&] { (void)reg.create("Thrower"); });
    EXPECT_TRUE(contains(viaType.what(), "libloom_throws_on_register.so")) << viaType.what();
}

// Creating a type that two plugins announce reports the duplicate (as `loom passes` does), instead of quietly
// using whichever library was found first.
TEST(PluginErrors, CreatingADuplicatedTypeIsAnError) {
    PluginRegistry reg({pluginDir(), badDir("duplicate")}, false);
    Error e = expectError([&] { (void)reg.create("Constant"); });
    EXPECT_TRUE(contains(e.what(), "registered twice")) << e.what();
    EXPECT_TRUE(contains(e.what(), "libloom_dup_a.so")) << e.what();
}

TEST(PluginErrors, DuplicateTypeNamesBothLibraries) {
    PluginRegistry reg({pluginDir(), badDir("duplicate")}, false);
    Error e = expectError([&] { reg.loadAll(); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_TRUE(contains(e.what(), "'Constant' is registered twice")) << e.what();
    EXPECT_TRUE(contains(e.what(), "libloom_testpasses.so")) << e.what();
    EXPECT_TRUE(contains(e.what(), "libloom_dup_a.so")) << e.what();
}

TEST(PluginErrors, DuplicateTypeThroughLoadLibrary) {
    PluginRegistry reg({pluginDir()}, false);
    ASSERT_NE(reg.create("Constant"), nullptr);
    Error e = expectError([&] { reg.loadLibrary(badDir("duplicate") / "libloom_dup_a.so"); });
    EXPECT_TRUE(contains(e.what(), "'Constant' is registered twice")) << e.what();
    EXPECT_TRUE(contains(e.what(), testPassesLib().string())) << e.what();
    EXPECT_TRUE(contains(e.what(), fs::weakly_canonical(badDir("duplicate") / "libloom_dup_a.so").string()))
        << e.what();
    // The first registration wins.
    EXPECT_EQ(reg.typeInfo("Constant")->library.string(), testPassesLib().string());
}

TEST(PluginErrors, MissingDependencyShowsDlerror) {
    PluginRegistry reg({badDir("missing_dep")}, false);
    Error e = expectError([&] { reg.loadLibrary(badDir("missing_dep") / "libloom_missing_dep.so"); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_TRUE(contains(e.what(), "cannot load plugin library")) << e.what();
    EXPECT_TRUE(contains(e.what(), "libloom_test_hidden_dep.so")) << e.what();
    EXPECT_TRUE(contains(e.what(), "cannot open shared object file")) << e.what();
    EXPECT_TRUE(contains(e.info().suggestion, "ldd")) << e.what();
    EXPECT_TRUE(contains(e.info().suggestion, "libloom_missing_dep.so")) << e.what();
    EXPECT_TRUE(contains(e.info().suggestion, "depends on")) << e.what();

    // The same through create() and the manifest.
    Error viaCreate = expectError([&] { (void)reg.create("MissingDep"); });
    EXPECT_TRUE(contains(viaCreate.what(), "libloom_test_hidden_dep.so")) << viaCreate.what();
}

TEST(PluginErrors, NotAPlugin) {
    PluginRegistry reg({badDir("not_plugin")}, false);
    Error e = expectError([&] { reg.loadLibrary(badDir("not_plugin") / "libloom_not_a_plugin.so"); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_TRUE(contains(e.what(), "not a Loom plugin")) << e.what();
    EXPECT_TRUE(contains(e.what(), "libloom_not_a_plugin.so")) << e.what();
    Error viaCreate = expectError([&] { (void)reg.create("Nothing"); });
    EXPECT_TRUE(contains(viaCreate.what(), "not a Loom plugin")) << viaCreate.what();
}

TEST(PluginErrors, ManifestNamesMissingLibrary) {
    PluginRegistry reg({badDir("missing_lib")}, false);
    EXPECT_TRUE(reg.knows("Gone"));
    Error e = expectError([&] { (void)reg.create("Gone"); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    EXPECT_TRUE(contains(e.what(), "not found")) << e.what();
    EXPECT_TRUE(contains(e.info().file, "libloom_gone.so")) << e.what();
    EXPECT_TRUE(contains(e.what(), "libloom_gone.so")) << e.what();
}

TEST(PluginErrors, LoadLibraryOfMissingFile) {
    PluginRegistry reg({}, false);
    Error e = expectError([&] { reg.loadLibrary("/nonexistent/libloom_nothing.so"); });
    EXPECT_TRUE(contains(e.what(), "not found")) << e.what();
    EXPECT_TRUE(contains(e.what(), "/nonexistent/libloom_nothing.so")) << e.what();
}

// ---------------------------------------------------------------------------------------------------------------
// Folders: LOOM_PLUGIN_PATH, libraries without a manifest, broken manifests

TEST(Plugins, PluginPathEnvironmentIsHonoured) {
    ScopedEnv env("LOOM_PLUGIN_PATH", "/nonexistent/a::" + pluginDir().string());
    {
        PluginRegistry reg({}, /*useEnvironment=*/true);
        ASSERT_EQ(reg.searchDirs().size(), 2u);  // the empty entry is skipped
        EXPECT_EQ(reg.searchDirs()[0], fs::path("/nonexistent/a"));
        EXPECT_EQ(reg.searchDirs()[1], pluginDir());
        auto constant = reg.create("Constant");
        ASSERT_NE(constant, nullptr);
        EXPECT_NE(constant->params().find("color"), nullptr);
    }
    {
        // Environment folders come after the explicit ones.
        PluginRegistry reg({badDir("abi")}, true);
        ASSERT_EQ(reg.searchDirs().size(), 3u);
        EXPECT_EQ(reg.searchDirs()[0], badDir("abi"));
        EXPECT_TRUE(reg.knows("Constant"));
        EXPECT_TRUE(reg.knows("BadAbi"));
    }
    {
        PluginRegistry reg({}, /*useEnvironment=*/false);
        EXPECT_TRUE(reg.searchDirs().empty());
        EXPECT_FALSE(reg.knows("Constant"));
    }
}

TEST(Plugins, PluginPathUnsetMeansNoExtraFolders) {
    ScopedEnv env("LOOM_PLUGIN_PATH", "");
    ::unsetenv("LOOM_PLUGIN_PATH");
    PluginRegistry reg({}, true);
    EXPECT_TRUE(reg.searchDirs().empty());
    EXPECT_TRUE(reg.knownTypes().empty());
}

TEST_F(PluginFiles, LibraryWithoutManifestIsLoadedWhenNeeded) {
    // A copy (not a link, so the loader sees a different file) of the test plugin, without its manifest.
    fs::copy_file(pluginDir() / "libloom_testpasses.so", mDir / "libloom_copy.so");
    write(mDir / "README.txt", "not a library");
    PluginRegistry reg({mDir}, false);
    EXPECT_TRUE(reg.knownTypes().empty());  // nothing is announced
    auto blur = reg.create("Blur");
    ASSERT_NE(blur, nullptr);
    EXPECT_NE(blur->params().find("radius"), nullptr);
    ASSERT_NE(reg.typeInfo("Blur"), nullptr);
    EXPECT_EQ(reg.typeInfo("Blur")->library, fs::weakly_canonical(mDir / "libloom_copy.so"));
    EXPECT_TRUE(hasType(reg.knownTypes(), "ToSrgb8"));  // registered now
}

TEST_F(PluginFiles, LoadAllLoadsLibrariesWithoutManifest) {
    fs::copy_file(pluginDir() / "libloom_testpasses.so", mDir / "libloom_copy2.so");
    PluginRegistry reg({mDir}, false);
    reg.loadAll();
    EXPECT_EQ(reg.registeredTypes().size(), kTestTypes.size());
}

TEST_F(PluginFiles, BrokenManifestsAreIgnored) {
    write(mDir / "libloom_syntax.json", "{ not json");
    write(mDir / "libloom_keys.json", R"({"lib": "libloom_keys.so"})");
    write(mDir / "libloom_types.json", R"({"library": 3, "types": "Blur"})");
    write(mDir / "libloom_items.json", R"({"library": "libloom_items.so", "types": [1, 2]})");
    write(mDir / "libloom_good.json", R"({"library": "libloom_good.so", "types": ["Good"]})");
    PluginRegistry reg({mDir}, false);
    std::vector<std::string> known;
    try {
        known = reg.knownTypes();
    } catch (const std::exception& e) {
        FAIL() << "a broken manifest must be ignored, not throw: " << e.what();
    }
    EXPECT_EQ(known, std::vector<std::string>{"Good"});
}
