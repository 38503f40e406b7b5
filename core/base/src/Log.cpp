#include "loom/Log.h"

namespace loom {

bool setLogLevel(const std::string& level) {
    auto l = spdlog::level::from_str(level);
    if (l == spdlog::level::off && level != "off") return false;
    spdlog::set_level(l);
    return true;
}

const char* version() { return LOOM_VERSION; }

}  // namespace loom
