// Scene and G-buffer benchmarks: glTF load time, and GBufferRT / GBufferRaster
// at 1280x720 with every channel consumed (readback included), per data scene.
#include <benchmark/benchmark.h>

#include <string>

#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

const char* kScenes[] = {"cornell_box.gltf", "cornell_dynamic.gltf", "materials.gltf"};

std::string scenePath(int i) { return std::string(LOOM_SOURCE_DIR) + "/data/scenes/" + kScenes[i]; }

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

void BM_GBufferRT(benchmark::State& state) { gbuffer(state, "GBufferRT"); }
void BM_GBufferRaster(benchmark::State& state) { gbuffer(state, "GBufferRaster"); }
BENCHMARK(BM_GBufferRT)->DenseRange(0, 2)->Unit(benchmark::kMillisecond)->UseRealTime();
BENCHMARK(BM_GBufferRaster)->DenseRange(0, 2)->Unit(benchmark::kMillisecond)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
