#pragma once
// What both G-buffer passes share: the standard channels they produce
// (loom/Channels.h), in one order, so the two passes stay interchangeable.
#include "loom/Channels.h"
#include "loom/Reflection.h"

namespace loom::gbuffer {

using namespace loom::channel;

/// The standard channel `name` (a compile-time error when there is none).
constexpr ChannelInfo standard(const char* name) {
    return *findStandardChannel(name);
}

/// The channels of a G-buffer, in the order of GBufferRaster's output bits and attachments.
inline constexpr ChannelInfo kChannels[] = {
    standard(kPosW),     standard(kNormW),   standard(kFaceNormalW), standard(kLinearZ),
    standard(kPnFwidth), standard(kMvec),    standard(kAlbedo),      standard(kSpecAlbedo),
    standard(kEmission), standard(kVBuffer), standard(kMeshId),
};

/// Which surfaces a G-buffer sees. Both passes bind their cullMode and alphaTest parameters to this struct, so its
/// members hold their defaults and the two passes stay interchangeable.
struct Visibility {
    enum class CullMode { None, Back };
    CullMode cullMode = CullMode::Back;  ///< Back: single-sided materials show only their front faces
    bool alphaTest = true;               ///< alphaMode MASK and BLEND apply; false: every material opaque
};

/// Declares every channel as an optional output: only consumed ones are computed.
inline void reflectChannels(Reflection& r) {
    for (const auto& c : kChannels) r.output(c.name, c.format).optional().doc(c.meaning);
}

}  // namespace loom::gbuffer
