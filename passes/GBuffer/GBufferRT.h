#pragma once
// GBufferRT: the standard G-buffer channels from Embree primary rays.
#include <memory>
#include <string>
#include <vector>

#include "GBufferCommon.h"
#include "loom/RenderPass.h"

namespace loom {

class GBufferRT final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    void execute(PassContext& ctx) override;
    void setScene(const std::shared_ptr<const Scene>& scene) override;
    std::vector<std::string> skippedWork() const override;

    using CullMode = gbuffer::Visibility::CullMode;

private:
    gbuffer::Visibility mVisibility;  ///< cullMode, alphaTest: the shared struct holds the defaults
    bool mSpecialize = true;
    std::shared_ptr<const Scene> mScene;  // for skippedWork
};

}  // namespace loom
