// The path tracer placed on a device by the graph: on `emulated` (the GPU path on CPU threads, its memory kept apart)
// the CUDA backend's kernels write every output, the temporal gradients and their history straight into the pass's
// device fields, and read the vbuffer there. Its fields equal, bit for bit, those of the same kernels run as the
// emulated backend placed on the CPU (`device: emulated`), at any thread count; a static scene's gradients are
// equal pairs; and in the shipped SVGF graph no output of the path tracer crosses devices.
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "../apps/loom/SceneSetup.h"
#include "TestUtil.h"
#include "loom/Device.h"
#include "loom/Parallel.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;
namespace fs = std::filesystem;

namespace {

constexpr uint32_t kW = 48, kH = 32;
const std::vector<std::string> kOutputs = {"color",      "direct",   "indirect", "albedo",
                                           "specAlbedo", "emission", "gradient"};

/// PathTracer "P" (after a GBufferRT "G" feeding its vbuffer when asked), every output marked and every field
/// observed (so the host copies of device fields can be read), on graph device `device`.
std::unique_ptr<RenderGraph> tracerGraph(const std::string& device, const nlohmann::json& params, bool vbuffer,
                                         const std::shared_ptr<Scene>& scene) {
    nlohmann::json g = {{"loom_graph", 1}, {"name", "devices"}, {"passes", nlohmann::json::array()}, {"outputs", {}}};
    // The G-buffer pinned to the CPU, so that both graphs read the same vbuffer (on the emulated device, through the
    // graph's transfer).
    if (vbuffer) g["passes"].push_back({{"name", "G"}, {"type", "GBufferRT"}, {"device", "cpu"}});
    g["passes"].push_back({{"name", "P"}, {"type", "PathTracer"}, {"params", params}});
    for (const std::string& o : kOutputs) g["outputs"].push_back("P." + o);
    CompileOptions o;
    o.device = device;
    o.observe = {"*"};
    return test::compiledGraph(g, scene, kW, kH, o);
}

/// The path tracer's fields in the plan: outputs and history (not the transfers' copies).
std::vector<std::string> tracerFields(const RenderGraph& g) {
    std::vector<std::string> out;
    for (const auto& r : g.plan().resources)
        if (r.name.rfind("P.", 0) == 0 && r.name.find(' ') == std::string::npos) out.push_back(r.name);
    return out;
}

DeviceKind placement(const RenderGraph& g, const std::string& pass) {
    for (const PlacedPass& p : g.plan().placement)
        if (p.name == pass) return p.device;
    ADD_FAILURE() << pass << " is not placed";
    return DeviceKind::Cpu;
}

/// Renders `frames` frames of `scene` (animated from t = 0 in steps of 0.25) with the emulated backend placed on the
/// CPU and with the pass placed on the emulated device, at 1 and 2 threads, and checks every field of the pass in
/// every frame bit for bit against the first run's.
void expectPlacementEqualsBackend(const std::string& sceneName, bool vbuffer, uint32_t frames) {
    const auto scene = Scene::load(test::dataScene(sceneName));
    const nlohmann::json base = {{"maxBounces", 3}, {"samplesPerPixel", 2}};
    nlohmann::json backendParams = base;
    backendParams["device"] = "emulated";
    // The reference: the emulated backend on the CPU at 1 thread, every field of every frame.
    std::vector<std::map<std::string, std::vector<float>>> reference(frames);
    std::vector<double> referenceRays(frames);
    const auto snapshot = [](const Texture& t) {
        std::vector<float> v;
        const uint32_t channels = formatInfo(t.format()).channels;
        for (uint32_t y = 0; y < t.height(); ++y)
            for (uint32_t x = 0; x < t.width(); ++x)
                for (uint32_t c = 0; c < channels; ++c) v.push_back(t.texel(x, y, c));
        return v;
    };
    for (unsigned threads : {1u, 2u}) {
        ThreadLimit limit(threads);
        auto backend = tracerGraph("cpu", backendParams, vbuffer, scene);
        auto placed = tracerGraph("emulated", base, vbuffer, scene);
        EXPECT_EQ(placement(*backend, "P"), DeviceKind::Cpu);
        EXPECT_EQ(placement(*placed, "P"), DeviceKind::Emulated);
        const std::vector<std::string> fields = tracerFields(*placed);
        // Every output and the gradients' history.
        EXPECT_EQ(fields.size(), kOutputs.size() + 2) << sceneName;
        for (uint32_t i = 0; i < frames; ++i) {
            const double t = 0.25 * double(i);
            const FrameInfo info = cli::sceneFrameAt(scene.get(), i, t, kW, kH, false);
            backend->execute(info);
            placed->execute(info);
            const std::string where =
                sceneName + " frame " + std::to_string(i) + ", " + std::to_string(threads) + " thread(s)";
            for (const std::string& f : fields) {
                const Texture* a = backend->fieldTexture(f);
                const Texture* b = placed->fieldTexture(f);
                ASSERT_TRUE(a && b) << f;
                ASSERT_TRUE(b->onHost()) << f << ": fieldTexture gives the host copy";
                EXPECT_TRUE(a->samePixels(*b)) << f << ", " << where;
                if (threads == 1u)
                    reference[i][f] = snapshot(*b);
                else
                    EXPECT_TRUE(reference[i][f] == snapshot(*b)) << f << " differs from 1 thread's, " << where;
            }
            const double rays = placed->lastStats().at("P").at("rays");
            EXPECT_EQ(rays, backend->lastStats().at("P").at("rays")) << where;
            if (threads == 1u)
                referenceRays[i] = rays;
            else
                EXPECT_EQ(rays, referenceRays[i]) << where;
        }
    }
}

}  // namespace

// Camera rays, an animated scene (moving instances: the gradients' replay follows them), three frames.
TEST(PathTracerDevices, EmulatedPlacementEqualsEmulatedBackendCornellDynamic) {
    expectPlacementEqualsBackend("cornell_dynamic.gltf", false, 3);
}

// Textures and a vbuffer read from device memory (GBufferRT's on the CPU, transferred to the emulated device).
TEST(PathTracerDevices, EmulatedPlacementEqualsEmulatedBackendMaterials) {
    expectPlacementEqualsBackend("materials.gltf", true, 2);
}

// Where nothing changes, the replay of last frame's samples is the same path with the same random numbers: every
// block's pair is equal (what A-SVGF's anti-lag reads as "no change") up to float rounding (the host compiler may
// fuse multiplies and adds differently in the two inlined copies of the path), and lit blocks are not zero.
TEST(PathTracerDevices, StaticSceneGradientsAreEqualPairs) {
    const auto scene = Scene::load(test::dataScene("cornell_box.gltf"));
    auto placed = tracerGraph("emulated", {{"maxBounces", 3}}, false, scene);
    for (uint32_t i = 0; i < 3; ++i) {
        placed->execute(cli::sceneFrameAt(scene.get(), i, 0.0, kW, kH, false));
        const Texture* g = placed->fieldTexture("P.gradient");
        ASSERT_TRUE(g);
        uint32_t lit = 0;
        for (uint32_t y = 0; y < kH; ++y)
            for (uint32_t x = 0; x < kW; ++x) {
                const float now = g->texel(x, y, 0), then = g->texel(x, y, 1);
                if (i == 0) {
                    EXPECT_EQ(now, 0.f) << "no history on the first frame";
                    continue;
                }
                EXPECT_LE(std::fabs(now - then), 1e-5f * std::max(now, then))
                    << "pixel " << x << "," << y << ", frame " << i;
                lit += now > 0.f;
            }
        if (i > 0) EXPECT_GT(lit, kW * kH / 4) << "frame " << i;
    }
}

// The shipped SVGF graph on emulated: the path tracer runs there, so its outputs reach SVGF and AccumulatePass
// without a transfer; only the G-buffer's fields (GBufferRaster runs on the CPU) and the marked output cross.
TEST(PathTracerDevices, SvgfGraphOnEmulatedTransfersNoPathTracerOutput) {
    const fs::path dir = fs::temp_directory_path() / ("loom_pt_devices_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const std::string graph = std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/PathTracerSVGF.json";
    const test::CliResult check = test::runLoom(dir, "check --device emulated " + test::shellQuoted(graph));
    fs::remove_all(dir);
    ASSERT_EQ(check.code, 0) << check.output;
    std::istringstream in(check.output);
    std::string line;
    bool inTransfers = false, placedOnEmulated = false;
    std::vector<std::string> transfers;
    while (std::getline(in, line)) {
        if (line.rfind("Transfers per frame", 0) == 0) {
            inTransfers = true;
            continue;
        }
        if (inTransfers && line.empty()) inTransfers = false;
        if (inTransfers) transfers.push_back(line);
        if (line.rfind("  PathTracer ", 0) == 0 && line.find(" emulated") != std::string::npos &&
            line.find("runs on the CPU") == std::string::npos)
            placedOnEmulated = true;
    }
    EXPECT_TRUE(placedOnEmulated) << check.output;
    ASSERT_FALSE(transfers.empty()) << check.output;
    bool vbuffer = false;
    for (const std::string& t : transfers) {
        EXPECT_EQ(t.find("PathTracer."), std::string::npos) << "a path tracer output crosses devices: " << t;
        const bool gbuffer = t.find("  GBuffer.") == 0, marked = t.find("(marked output)") != std::string::npos;
        EXPECT_TRUE(gbuffer || marked) << t;
        vbuffer = vbuffer ||
                  (t.find("GBuffer.vbuffer") != std::string::npos && t.find("cpu -> emulated") != std::string::npos);
    }
    EXPECT_TRUE(vbuffer) << "the vbuffer goes to the path tracer's device: " << check.output;
}
