#pragma once
// Logging through spdlog, with one place that sets the level.
#include <string>

#include <spdlog/spdlog.h>

namespace loom {

/// Sets the log level by name: trace, debug, info, warn, error, off.
/// Returns false for an unknown name.
bool setLogLevel(const std::string& level);
/// Loom's version string.
const char* version();

}  // namespace loom
