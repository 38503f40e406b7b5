#pragma once
// GBufferRT: the standard G-buffer channels from Embree primary rays.
#include "GBufferCommon.h"
#include "loom/RenderPass.h"

namespace loom {

class GBufferRT final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    void execute(PassContext& ctx) override;

    using CullMode = gbuffer::Visibility::CullMode;

private:
    gbuffer::Visibility mVisibility;  ///< cullMode, alphaTest: the shared struct holds the defaults
};

}  // namespace loom
