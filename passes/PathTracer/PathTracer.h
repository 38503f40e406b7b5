#pragma once
// PathTracer (also registered as CUDAPathTracer): unidirectional path tracing
// with NEE and MIS over emissive triangles, punctual lights and the
// environment. Runs on the CPU (Embree + oneTBB), or on an NVIDIA GPU through
// the CUDA backend (CudaBackend.h, PixelKernel.h: the same kernels over a BVH of
// its own, loom/Bvh.h), which `device` selects.
#include <glm/glm.hpp>
#include <memory>
#include <string>
#include <vector>

#include "Lights.h"
#include "PathTracerKernels.h"
#include "loom/Bvh.h"
#include "loom/RenderPass.h"

namespace loom {

namespace pt {
class CudaBackend;
}

class PathTracer final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo& info) const override;
    void declareParams(ParamList& p) override;
    void compile(const CompileInfo& info) override;
    void execute(PassContext& ctx) override;
    void setScene(const std::shared_ptr<const Scene>& scene) override;
    PathTracer();
    ~PathTracer() override;
    std::vector<std::string> skippedWork() const override;
    bool runsOn(DeviceKind device) const override;

    enum class Device { Auto, Cpu, Cuda, Emulated };
    enum class CullMode { None, Back };
    enum class EmissionWeights { Texture, Area };
    enum class PixelFilter { Center, Box };

private:
    void buildLights(const Scene& scene);
    void buildEnvironment(const Scene& scene);
    const std::vector<float>& triangleEmission(const Scene& scene, uint32_t instance);
    /// The pt::KernelFeature bits of the kernel the current light list needs (kAllFeatures unless specialize).
    uint32_t kernelFeatures() const;
    /// The BVH of `scene` with its instances where they are now (built on the first call for a scene or geometry).

    /// Where frames run when the graph places the pass on the CPU, decided at compile from `device` (placed on a
    /// device, the CUDA backend's kernels run there, whatever `device` says).
    enum class Backend { Cpu, Cuda, Emulated };
    Backend mActive = Backend::Cpu;
    std::unique_ptr<pt::CudaBackend> mCuda;
    SceneBvh mBvh;  ///< moving instances rebuild only its top level (the CUDA backend re-uploads only that)

    // Parameters.
    /// maxBounces, rrStartBounce, lightSampling, lambertOnly, energyCompensation, indirectClamp: the kernel's struct
    /// holds the defaults
    pt::PathTracerSettings mSettings;
    int mSamplesPerPixel = 1;
    Device mDevice = Device::Auto;
    int mSeed = 0;
    bool mSimdShading = true;
    CullMode mCullMode = CullMode::Back;
    bool mAlphaTest = true;
    EmissionWeights mEmissionWeights = EmissionWeights::Texture;
    PixelFilter mPixelFilter = PixelFilter::Center;
    bool mSpecialize = true;

    // Light data, rebuilt per frame (triangles, punctual lights: animated emission is followed) or per scene
    // (environment).
    std::vector<pt::EmissiveTri> mTris;
    std::vector<float> mTriCdf;
    std::vector<uint32_t> mInstanceTriBase;
    std::vector<pt::PunctualLight> mPunctual;
    std::vector<float> mEnvMarginal, mEnvConditional;
    const void* mEnvSource = nullptr;  // the scene whose environment the CDFs describe
    // Per mesh of an emissive-textured material: the mean emitted luminance over each triangle (empty until an
    // instance of the mesh is first lit), for the scene mEmissionSource.
    std::vector<std::vector<float>> mTriEmission;
    std::vector<glm::vec3> mTriEmissionFactor;  // per mesh: the emissive factor its means were measured with
    const void* mEmissionSource = nullptr;
    pt::LightsView mLights;
    // The scene and parameters the light list was built for (a static scene's is built once).
    const void* mLightsSource = nullptr;
    std::shared_ptr<const Scene> mScene;  // the scene set, for skippedWork before the first frame
    uint64_t mLightsVersion = 0;
    bool mLightsAlphaTest = true;
    EmissionWeights mLightsWeights = EmissionWeights::Texture;
    uint32_t mKernelFeatures = 3u;  // pt::kAllFeatures
    bool mSimdUsed = true;          // the last frame shaded with the SIMD kernel
    bool mEmitterSurfaces = true;   // a light sample evaluates an emitter's material (textured or alpha-tested)
};

}  // namespace loom
