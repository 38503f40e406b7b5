#pragma once
// GBufferRT: the standard G-buffer channels from Embree primary rays.
#include "loom/RenderPass.h"

namespace loom {

class GBufferRT final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    void execute(PassContext& ctx) override;

    enum class CullMode { None, Back };

private:
    CullMode mCullMode = CullMode::Back;
    bool mAlphaTest = true;
};

}  // namespace loom
