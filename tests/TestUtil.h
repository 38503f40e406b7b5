#pragma once
// Helpers shared by the test files.
#include <gtest/gtest.h>

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

}  // namespace loom::test
