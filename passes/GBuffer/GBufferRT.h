#pragma once
// GBufferRT: the standard G-buffer channels from Embree primary rays.
#include <memory>
#include <string>
#include <vector>

#include "loom/RenderPass.h"

namespace loom {

class GBufferRT final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    void execute(PassContext& ctx) override;
    void setScene(const std::shared_ptr<const Scene>& scene) override;
    std::vector<std::string> skippedWork() const override;

    enum class CullMode { None, Back };

private:
    CullMode mCullMode = CullMode::Back;
    bool mAlphaTest = true;
    bool mSpecialize = true;
    std::shared_ptr<const Scene> mScene;  // for skippedWork
};

}  // namespace loom
