// Throws while registering, as a plugin whose set-up fails might: an exception that is not a std::exception.
#include "loom/Plugin.h"

LOOM_DEFINE_PLUGIN(r) {
    (void)r;
    throw 7;
}
