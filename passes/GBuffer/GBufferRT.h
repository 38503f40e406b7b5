#pragma once
// GBufferRT: the standard G-buffer channels from primary rays: Embree's on the CPU, the scene's BVH (loom/Bvh.h)
// traversed by the same kernel on emulated and cuda (GBufferRTDevice.h).
#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "GBufferCommon.h"
#include "GBufferRTDevice.h"
#include "loom/Bvh.h"
#include "loom/RenderPass.h"

namespace loom {

class Scene;

class GBufferRT final : public RenderPass {
public:
    GBufferRT();
    ~GBufferRT() override;
    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    void execute(PassContext& ctx) override;
    void setScene(const std::shared_ptr<const Scene>& scene) override;
    std::vector<std::string> skippedWork() const override;
    bool runsOn(DeviceKind device) const override;

    using CullMode = gbuffer::Visibility::CullMode;

private:
    gbuffer::Visibility mVisibility;  ///< cullMode, alphaTest: the shared struct holds the defaults
    bool mSpecialize = true;
    std::shared_ptr<const Scene> mScene;  // for skippedWork

    // Off the CPU: the scene's BVH, rebuilt when the scene or its meshes change (else only its top level), and its
    // arrays where the device reads them (uploaded again when mBvh.builds() changes).
    void executeOnDevice(PassContext& ctx, const Scene& scene, const gbuffer::device::TraceParams& params,
                         const gbuffer::GBufferViews& out);
    SceneBvh mBvh;
    std::unique_ptr<gbuffer::device::DeviceScene> mDeviceScene;
};

}  // namespace loom
