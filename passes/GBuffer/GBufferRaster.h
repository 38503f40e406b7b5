#pragma once
// GBufferRaster: the standard G-buffer channels rasterized with OpenGL 4.5 in
// a headless EGL context (llvmpipe on machines without a GPU), read back into
// the graph's host textures. Only consumed channels are drawn and read.
#include <memory>

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

    enum class CullMode { None, Back };

private:
    struct Gpu;  // the GL context and every GL object (GBufferRaster.cpp)
    Gpu& gpu();

    CullMode mCullMode = CullMode::Back;
    bool mAlphaTest = true;
    std::shared_ptr<const Scene> mScene;
    std::unique_ptr<Gpu> mGpu;
};

}  // namespace loom
