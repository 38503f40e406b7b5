// A plugin built for another ABI version: loading it must fail cleanly.
#include "loom/Plugin.h"

LOOM_PLUGIN_EXPORT uint32_t loomPluginAbiVersion() { return LOOM_PLUGIN_ABI_VERSION + 1000; }
LOOM_PLUGIN_EXPORT void loomRegisterPlugin(loom::PluginRegistrar&) {}
