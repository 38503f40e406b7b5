#pragma once
// GBufferRaster: the standard G-buffer channels rasterized with OpenGL 4.5 in
// a headless EGL context (llvmpipe on machines without a GPU), read back into
// the graph's host textures. Only consumed channels are drawn and read.
//
// What it writes, and where it differs from GBufferRT:
// - Values at a hit (posW, normals, vbuffer barycentrics, material channels,
//   mvec) come from the triangle fetched by gl_PrimitiveID and the pixel's
//   exact camera ray, by SurfaceKernels.h's formulas: they match GBufferRT
//   to float rounding (textures: to GL's 8-bit filtering weights).
// - Derivatives (linearZ.y, pnFwidth) are GL's fine dFdx/dFdy: differences
//   within each 2x2 pixel quad, so backward differences in odd columns and
//   rows where GBufferRT always differences forward. pnFwidth.y is that of
//   the interpolated vertex normal (before normal mapping), as in GBufferRT.
// - Misses: posW, normals, albedo, specAlbedo, emission 0 (w 0 too),
//   linearZ (-1, 0), vbuffer and meshId ~0u, and mvec the motion of the
//   pixel's direction at infinity under the previous camera's rotation
//   (CameraKernels.h missMotion), as GBufferRT.
// - Geometry closer than the camera's nearZ is clipped; there is no far plane.
// - alphaMode MASK and BLEND (stochastic transparency) decide as GBufferRT's
//   rays do (SurfaceKernels.h surfaceCovers, the same hash of pixel, frame,
//   instance and triangle); textured alpha comes from GL's filtering, so it
//   agrees to 8-bit filter weights, factors exactly.
// The context is current only inside execute/setScene (and restored after).
#include <memory>

#include "GBufferCommon.h"
#include "loom/RenderPass.h"

namespace loom {

class GBufferRaster final : public RenderPass {
public:
    GBufferRaster();
    ~GBufferRaster() override;

    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    void compile(const CompileInfo& info) override;
    void execute(PassContext& ctx) override;
    /// Uploads the scene now. A frame's scene (PassContext::scene) takes
    /// precedence when it is a different one; this one is used for frames
    /// that come without a scene.
    void setScene(const std::shared_ptr<const Scene>& scene) override;
    std::vector<std::string> skippedWork() const override;

    using CullMode = gbuffer::Visibility::CullMode;

private:
    struct Gpu;  // the GL context and every GL object (GBufferRaster.cpp)
    Gpu& gpu();

    gbuffer::Visibility mVisibility;  ///< cullMode, alphaTest: the shared struct holds the defaults
    bool mSpecialize = true;
    std::shared_ptr<const Scene> mScene;
    std::unique_ptr<Gpu> mGpu;
};

}  // namespace loom
