#pragma once
// Helpers shared by the test files.
#include <gtest/gtest.h>
#include <unistd.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <functional>
#include <glm/vec4.hpp>
#include <memory>
#include <string>

#include "loom/Error.h"
#include "loom/Plugin.h"
#include "loom/RenderPass.h"

namespace loom::test {

/// Runs `fn`, expects a loom::Error, and returns it (a default-constructed one when nothing was thrown).
template <class Fn>
Error expectError(Fn&& fn) {
    try {
        fn();
    } catch (const Error& e) {
        return e;
    } catch (const std::exception& e) {
        ADD_FAILURE() << "expected loom::Error, got another exception: " << e.what();
        return Error({});
    }
    ADD_FAILURE() << "expected loom::Error, nothing was thrown";
    return Error({});
}

/// One registry over the build's plugin folder, shared by a test binary (a type registers once per registry).
inline PluginRegistry& pluginRegistry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    return r;
}

/// A test pass that emits "color" = fn(frame index, x, y) (zero without fn): any frame-dependent input a test
/// needs. Registered as "FunctionSource" by registryWithFunctionSource().
class FunctionSource final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override { r.output("color", Format::RGBA32F); }
    void execute(PassContext& ctx) override {
        auto dst = ctx.output("color")->view<glm::vec4>();
        for (uint32_t y = 0; y < dst.height; ++y)
            for (uint32_t x = 0; x < dst.width; ++x) dst.at(x, y) = fn ? fn(ctx.frameIndex(), x, y) : glm::vec4(0.f);
    }
    std::function<glm::vec4(uint64_t frame, uint32_t x, uint32_t y)> fn;
};

/// A registry over the build's plugin folder with FunctionSource registered (its own registry, so tests that
/// add a type do not change the shared one).
inline PluginRegistry& registryWithFunctionSource() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    static const bool registered = [] {
        r.registerPass("FunctionSource", "frame-dependent test input",
                       [] { return std::make_unique<FunctionSource>(); });
        return true;
    }();
    (void)registered;
    return r;
}

/// Path of a scene shipped in data/scenes.
inline std::string dataScene(const std::string& name) {
    return std::string(LOOM_TEST_SOURCE_DIR) + "/data/scenes/" + name;
}

/// A fresh folder per test (named after the suite and test), removed afterwards.
class TempDirTest : public ::testing::Test {
protected:
    void SetUp() override {
        const auto* test = ::testing::UnitTest::GetInstance()->current_test_info();
        mDir = std::filesystem::temp_directory_path() / ("loom_test_" + std::string(test->test_suite_name()) + "_" +
                                                         std::to_string(::getpid()) + "_" + test->name());
        std::filesystem::remove_all(mDir);
        std::filesystem::create_directories(mDir);
    }
    void TearDown() override {
        std::error_code ec;
        std::filesystem::remove_all(mDir, ec);
    }
    void write(const std::filesystem::path& p, const std::string& text) {
        std::ofstream out(p, std::ios::binary);
        out << text;
    }
    std::filesystem::path mDir;
};

}  // namespace loom::test
