#pragma once
// Helpers shared by the test files.
#include <gtest/gtest.h>

#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "loom/Error.h"
#include "loom/Plugin.h"

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
