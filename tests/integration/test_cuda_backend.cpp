// The path tracer's CUDA backend. Its kernels (PixelKernel.h over the BVH of loom/BvhTraversal.h) run on the host
// as device "emulated": a whole frame of them equals the CPU path tracer's (Embree) with the same random numbers,
// wherever the two traversals find the same hits, on scenes with textures, single-sided faces, an environment
// map, animation, a vbuffer and every output (the temporal gradients, which the CPU computes after either). On a
// machine with a CUDA device the same frame runs on the GPU and is compared with the CPU's the same way; without
// one that test is skipped, saying why.
#include <dlfcn.h>
#include <gtest/gtest.h>

#include <cmath>
#include <iostream>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "../apps/loom/SceneSetup.h"
#include "TestUtil.h"
#include "loom/Error.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

constexpr uint32_t kW = 64, kH = 48;
const std::vector<std::string> kOutputs = {"color",      "direct",   "indirect", "albedo",
                                           "specAlbedo", "emission", "gradient"};

/// PathTracer "P" alone (or after a GBufferRT "G" feeding its vbuffer), every output marked.
std::unique_ptr<RenderGraph> tracerGraph(const std::string& device, nlohmann::json params, bool vbuffer,
                                         const std::shared_ptr<Scene>& scene) {
    params["device"] = device;
    nlohmann::json g = {{"loom_graph", 1}, {"name", "cuda"}, {"passes", nlohmann::json::array()}, {"outputs", {}}};
    if (vbuffer) g["passes"].push_back({{"name", "G"}, {"type", "GBufferRT"}});
    g["passes"].push_back({{"name", "P"}, {"type", "PathTracer"}, {"params", params}});
    for (const std::string& o : kOutputs) g["outputs"].push_back("P." + o);
    return test::compiledGraph(g, scene, kW, kH);
}

/// How two images of a frame compare: the share of pixels equal within float tolerance (every channel within
/// 1e-4 relative, 1e-6 absolute) and the largest difference elsewhere.
struct Agreement {
    double equalShare = 0.0;
    double meanAbsDiff = 0.0;
};

Agreement compare(const Texture& a, const Texture& b) {
    uint64_t equal = 0;
    double sumDiff = 0.0;
    const uint32_t channels = formatInfo(a.format()).channels;
    for (uint32_t y = 0; y < a.height(); ++y)
        for (uint32_t x = 0; x < a.width(); ++x) {
            bool same = true;
            for (uint32_t c = 0; c < channels; ++c) {
                const double u = a.texel(x, y, c), v = b.texel(x, y, c), d = std::fabs(u - v);
                sumDiff += d;
                same = same && d <= 1e-6 + 1e-4 * std::max(std::fabs(u), std::fabs(v));
            }
            equal += same;
        }
    const double n = double(a.width()) * a.height();
    return {double(equal) / n, sumDiff / (channels * n)};
}

/// Renders `frames` frames of `scene` with the CPU path tracer and with `device`, in lockstep, and checks every
/// output of every frame: at least 98.5 % of the pixels equal within float tolerance (a ray whose hit the two
/// traversals decide differently sends its path elsewhere; a gradient spans a 3x3 block, so one such path changes
/// nine of its pixels), and the rest small on average. Measured: 98.8 to 100 %.
void expectAgreement(const std::shared_ptr<Scene>& scene, const std::string& device, nlohmann::json params,
                     bool vbuffer, uint32_t frames, const std::string& label) {
    auto cpu = tracerGraph("cpu", params, vbuffer, scene);
    auto other = tracerGraph(device, params, vbuffer, scene);
    for (uint32_t i = 0; i < frames; ++i) {
        const double t = 0.25 * double(i);
        const FrameInfo info = cli::sceneFrameAt(scene.get(), i, t, kW, kH, false);
        cpu->execute(info);
        other->execute(info);
        for (const std::string& o : kOutputs) {
            const Agreement a = compare(*cpu->fieldTexture("P." + o), *other->fieldTexture("P." + o));
            EXPECT_GE(a.equalShare, 0.985) << label << ": P." << o << ", frame " << i;
            EXPECT_LE(a.meanAbsDiff, 0.01) << label << ": P." << o << ", frame " << i;
            if (o == "color")
                std::cout << "[ " << label << " frame " << i << " ] " << device << " vs cpu: " << 100.0 * a.equalShare
                          << " % of pixels equal, mean |difference| " << a.meanAbsDiff << "\n";
        }
        const double raysCpu = cpu->lastStats().at("P").at("rays");
        const double raysOther = other->lastStats().at("P").at("rays");
        EXPECT_NEAR(raysOther, raysCpu, 0.01 * raysCpu) << label << ", frame " << i;
    }
}

std::shared_ptr<Scene> shipped(const std::string& name) {
    return Scene::load(test::dataScene(name));
}

}  // namespace

TEST(CudaKernelsOnHost, FramesEqualTheCpuPathTracers) {
    const nlohmann::json base = {{"maxBounces", 3}, {"samplesPerPixel", 2}, {"simdShading", false}};
    expectAgreement(shipped("cornell_box.gltf"), "emulated", base, false, 2, "cornell_box");
    expectAgreement(shipped("cornell_dynamic.gltf"), "emulated", base, false, 3, "cornell_dynamic (animated)");
    expectAgreement(shipped("materials.gltf"), "emulated", base, true, 2, "materials (textures, vbuffer)");
    expectAgreement(shipped("materials.gltf"), "emulated", base, false, 1, "materials (camera rays)");
    nlohmann::json box = base;
    box["pixelFilter"] = "box";
    box["lightSampling"] = "nee";
    expectAgreement(shipped("materials.gltf"), "emulated", box, false, 1, "materials (box filter, NEE)");
    auto sky = shipped("sky_sphere.gltf");
    sky->environment.width = 16;
    sky->environment.height = 8;
    for (uint32_t i = 0; i < 16 * 8; ++i)
        sky->environment.texels.push_back(glm::vec3(0.2f + 0.1f * float(i % 5), 0.3f + 0.2f * float(i % 3), 0.6f));
    expectAgreement(sky, "emulated", base, false, 1, "sky_sphere (environment map)");
}

// The default CPU path shades several paths at once in SIMD lanes: its frames agree with the kernels' too.
TEST(CudaKernelsOnHost, FramesEqualTheSimdCpuPathTracers) {
    expectAgreement(shipped("cornell_dynamic.gltf"), "emulated", {{"maxBounces", 3}, {"samplesPerPixel", 1}}, false, 2,
                    "cornell_dynamic, SIMD shading");
}

// With a CUDA device: the frame on the GPU against the CPU's. Without one (or in a build without the backend)
// device "cuda" is an error saying so, and the test is skipped with that message.
TEST(CudaDevice, FramesEqualTheCpuPathTracers) {
    auto scene = shipped("cornell_dynamic.gltf");
    std::string why;
    try {
        tracerGraph("cuda", {}, false, scene);
    } catch (const Error& e) {
        why = e.what();
    }
    if (!why.empty()) {
        EXPECT_NE(why.find("device 'cuda'"), std::string::npos) << why;
        // A machine without the NVIDIA driver is told so, not that its driver is too old.
        void* driver = dlopen("libcuda.so.1", RTLD_LAZY | RTLD_LOCAL);
        if (driver)
            dlclose(driver);
        else if (why.find("no CUDA support") == std::string::npos)
            EXPECT_NE(why.find("no NVIDIA GPU or driver"), std::string::npos) << why;
        GTEST_SKIP() << "no CUDA device here: " << why;
    }
    const nlohmann::json base = {{"maxBounces", 3}, {"samplesPerPixel", 2}, {"simdShading", false}};
    expectAgreement(scene, "cuda", base, false, 3, "cornell_dynamic on the GPU");
    expectAgreement(shipped("materials.gltf"), "cuda", base, true, 2, "materials on the GPU (vbuffer)");
}
