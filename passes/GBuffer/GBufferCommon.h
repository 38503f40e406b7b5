#pragma once
// The channels both G-buffer passes produce (DESIGN.md, "Standard channel
// names"), declared once so the two passes stay interchangeable.
#include "loom/Reflection.h"

namespace loom::gbuffer {

inline constexpr char kPosW[] = "posW";
inline constexpr char kNormW[] = "normW";
inline constexpr char kFaceNormalW[] = "faceNormalW";
inline constexpr char kLinearZ[] = "linearZ";
inline constexpr char kPnFwidth[] = "pnFwidth";
inline constexpr char kMvec[] = "mvec";
inline constexpr char kAlbedo[] = "albedo";
inline constexpr char kSpecAlbedo[] = "specAlbedo";
inline constexpr char kEmission[] = "emission";
inline constexpr char kVBuffer[] = "vbuffer";
inline constexpr char kMeshId[] = "meshId";

struct ChannelDecl {
    const char* name;
    Format format;
    const char* doc;
};

inline constexpr ChannelDecl kChannels[] = {
    {kPosW, Format::RGBA32F, "world position; w = 1 on a hit, 0 on a miss"},
    {kNormW, Format::RGBA32F, "shading normal, world space (w = 0)"},
    {kFaceNormalW, Format::RGBA32F, "geometric normal, world space (w = 0)"},
    {kLinearZ, Format::RG32F, "x: view depth (-1 on a miss), y: max(|ddx|, |ddy|) of x"},
    {kPnFwidth, Format::RG32F, "x: length of fwidth(posW), y: length of fwidth(normW)"},
    {kMvec, Format::RG32F, "uvPrev - uvCur over the frame, jitter removed"},
    {kAlbedo, Format::RGBA32F, "diffuse reflectance baseColor * (1 - metallic)"},
    {kSpecAlbedo, Format::RGBA32F, "directional specular reflectance (GGX, Karis fit)"},
    {kEmission, Format::RGBA32F, "emitted radiance"},
    {kVBuffer, Format::RGBA32U, "instance id, primitive id, barycentrics u, v (float bits); miss = ~0u"},
    {kMeshId, Format::R32U, "instance id for disocclusion tests; miss = ~0u"},
};

/// Declares every channel as an optional output: only consumed ones are computed.
inline void reflectChannels(Reflection& r) {
    for (const auto& c : kChannels) r.output(c.name, c.format).optional().doc(c.doc);
}

}  // namespace loom::gbuffer
