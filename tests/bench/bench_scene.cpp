// Scene and G-buffer benchmarks: glTF load time, GBufferRT / GBufferRaster at 1280x720 with every channel consumed
// (readback included), and closest-hit queries of the BVH the CUDA device traverses (run on the host) against
// Embree's, per data scene.
#include <benchmark/benchmark.h>

#include <cmath>
#include <string>
#include <vector>

#include "loom/Bvh.h"
#include "loom/BvhTraversal.h"
#include "loom/RayScene.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

const char* kScenes[] = {"cornell_box.gltf", "cornell_dynamic.gltf", "materials.gltf"};

std::string scenePath(int i) {
    return std::string(LOOM_SOURCE_DIR) + "/data/scenes/" + kScenes[i];
}

PluginRegistry& registry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    return r;
}

void BM_SceneLoad(benchmark::State& state) {
    for (auto _ : state) {
        auto scene = Scene::load(scenePath(int(state.range(0))));
        benchmark::DoNotOptimize(scene->triangleCount());
    }
    state.SetLabel(kScenes[state.range(0)]);
}
BENCHMARK(BM_SceneLoad)->DenseRange(0, 2)->Unit(benchmark::kMillisecond);

void gbuffer(benchmark::State& state, const char* type) {
    auto scene = Scene::load(scenePath(int(state.range(0))));
    const uint32_t W = 1280, H = 720;
    GraphDesc g = parseGraph(std::string(R"({"loom_graph": 1, "passes": [{"name": "GBuffer", "type": ")") + type +
                             R"("}], "outputs": ["GBuffer.posW", "GBuffer.normW", "GBuffer.faceNormalW",
                             "GBuffer.linearZ", "GBuffer.pnFwidth", "GBuffer.mvec", "GBuffer.albedo",
                             "GBuffer.specAlbedo", "GBuffer.emission", "GBuffer.vbuffer", "GBuffer.meshId"]})");
    RenderGraph graph(g, registry());
    graph.setScene(scene);
    CompileOptions o;
    o.width = W;
    o.height = H;
    graph.compile(o);
    uint64_t frame = 0;
    scene->camera.aspect = float(W) / float(H);
    for (auto _ : state) {
        scene->update(double(frame) / 60.0);
        scene->camera.beginFrame(frame);
        graph.execute(FrameInfo{frame, double(frame) / 60.0, scene.get(), &scene->camera});
        ++frame;
    }
    state.SetLabel(kScenes[state.range(0)]);
}

void BM_GBufferRT(benchmark::State& state) {
    gbuffer(state, "GBufferRT");
}
void BM_GBufferRaster(benchmark::State& state) {
    gbuffer(state, "GBufferRaster");
}
BENCHMARK(BM_GBufferRT)->DenseRange(0, 2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_GBufferRaster)->DenseRange(0, 2)->Unit(benchmark::kMillisecond)->UseRealTime();

/// Closest hits of random rays (origins in the scene's bounds, uniform directions), one thread: arg 1 = 0 the BVH
/// traversal of the CUDA device run on the host, 1 Embree (RayScene::intersect). Rays/s are the counter.
void BM_RayIntersect(benchmark::State& state) {
    auto scene = Scene::load(scenePath(int(state.range(0))));
    scene->update(0.0);
    const bool embree = state.range(1) == 1;
    const Bvh bvh(*scene);
    const BvhView view = bvh.view(scene->view());
    const Bounds b = scene->bounds();
    std::vector<glm::vec3> origins, dirs;
    uint32_t s = 1;
    auto next = [&] {
        s = s * 1664525u + 1013904223u;
        return float(s >> 8) / float(1u << 24);
    };
    for (int i = 0; i < 4096; ++i) {
        origins.push_back(b.lo + b.extent() * glm::vec3(next(), next(), next()));
        const float z = 1.f - 2.f * next(), phi = 6.2831853f * next(), r = std::sqrt(std::max(0.f, 1.f - z * z));
        dirs.emplace_back(r * std::cos(phi), r * std::sin(phi), z);
    }
    uint64_t rays = 0;
    for (auto _ : state) {
        for (size_t i = 0; i < origins.size(); ++i) {
            const RayHit h =
                embree ? scene->rayScene().intersect(origins[i], dirs[i]) : bvhIntersect(view, origins[i], dirs[i]);
            benchmark::DoNotOptimize(h);
        }
        rays += origins.size();
    }
    state.counters["rays/s"] = benchmark::Counter(double(rays), benchmark::Counter::kIsRate);
    state.SetLabel(std::string(kScenes[state.range(0)]) + (embree ? ", Embree" : ", Bvh"));
}
BENCHMARK(BM_RayIntersect)->ArgsProduct({{0, 1, 2}, {0, 1}})->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
