// The default graphs converge while nothing moves: their AccumulatePass blends the denoiser's image with the running
// mean of the path tracer's samples (AccumulateKernels.h, blendDenoised). Under motion they give the denoiser's images
// bit for bit; still, their error against the mean's limit falls like 1 / frames and drops below the denoiser's; a
// camera move or a parameter change upstream restarts from the denoiser's image in one frame. The blend on its own:
// passes/Accumulate/tests/.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <glm/gtc/matrix_transform.hpp>
#include <memory>
#include <string>
#include <vector>

#include "../apps/loom/SceneSetup.h"
#include "TestUtil.h"
#include "loom/Graph.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

const uint32_t kSize = 64;

std::string graphPath(const std::string& name) {
    return std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/" + name;
}

/// The shipped graph as it was before it converged: its AccumulatePass taken out, the denoised image wired straight
/// into the tone map.
GraphDesc withoutAccumulate(GraphDesc d) {
    ChannelRef denoised;
    std::vector<EdgeDesc> edges;
    for (const EdgeDesc& e : d.edges) {
        if (e.dst.pass == "Accumulate" && e.dst.channel == "denoised") denoised = e.src;
        if (e.src.pass != "Accumulate" && e.dst.pass != "Accumulate") edges.push_back(e);
    }
    EXPECT_FALSE(denoised.pass.empty()) << "no edge into Accumulate.denoised";
    edges.push_back(EdgeDesc{denoised, ChannelRef{"ToneMap", "src"}});
    d.edges = std::move(edges);
    d.passes.erase(
        std::remove_if(d.passes.begin(), d.passes.end(), [](const PassDesc& p) { return p.name == "Accumulate"; }),
        d.passes.end());
    return d;
}

/// One graph on its own copy of cornell_box, frame after frame at 60 fps.
struct GraphRun {
    GraphRun(const GraphDesc& desc, CameraPathKind path, std::vector<std::string> observe)
        : scene(Scene::load(test::dataScene("cornell_box.gltf"))),
          graph(std::make_unique<RenderGraph>(desc, test::pluginRegistry())) {
        scene->cameraPath.kind = path;
        graph->setScene(scene);
        CompileOptions o;
        o.width = o.height = kSize;
        o.observe = std::move(observe);
        graph->compile(o);
    }
    void step() {
        graph->execute(cli::sceneFrame(*scene, frame, 60.0, kSize, kSize, frame == 0));
        ++frame;
    }
    const Texture& field(const std::string& name) const {
        const Texture* t = graph->fieldTexture(name);
        if (!t) throw std::runtime_error("no field " + name);
        return *t;
    }
    double stat(const std::string& pass, const std::string& name) const { return graph->lastStats().at(pass).at(name); }

    std::shared_ptr<Scene> scene;
    std::unique_ptr<RenderGraph> graph;
    uint64_t frame = 0;
};

std::vector<glm::vec3> rgb(const Texture& t) {
    std::vector<glm::vec3> out;
    const auto v = t.view<glm::vec4>();
    for (uint32_t y = 0; y < t.height(); ++y)
        for (uint32_t x = 0; x < t.width(); ++x) out.emplace_back(v.at(x, y));
    return out;
}

/// The limit the default graph's running mean converges to (its path tracer's own image, clamp included), as the mean
/// of `batches` independent batches of `spp` samples per pixel, with the variance of that mean per pixel.
struct Reference {
    std::vector<glm::vec3> mean, variance;
};

Reference referenceOf(const std::string& graph, uint32_t batches, uint32_t spp) {
    GraphRun r(loadGraph(graphPath(graph)), CameraPathKind::Static, {"PathTracer.color"});
    r.graph->setParam("PathTracer", "samplesPerPixel", spp, "reference");
    std::vector<std::vector<glm::vec3>> images;
    for (uint32_t b = 0; b < batches; ++b) {
        r.graph->setParam("PathTracer", "seed", 1000 + int(b), "reference");  // independent of the runs' seed 0
        r.graph->resetHistory();
        r.frame = 0;
        r.step();
        images.push_back(rgb(r.field("PathTracer.color")));
    }
    Reference ref;
    ref.mean.assign(images[0].size(), glm::vec3(0.f));
    ref.variance.assign(images[0].size(), glm::vec3(0.f));
    for (const auto& im : images)
        for (size_t i = 0; i < im.size(); ++i) ref.mean[i] += im[i] / float(batches);
    for (const auto& im : images)
        for (size_t i = 0; i < im.size(); ++i)
            ref.variance[i] += (im[i] - ref.mean[i]) * (im[i] - ref.mean[i]) / float(batches - 1) / float(batches);
    return ref;
}

/// RelMSE (docs/METRICS.md) of `image` against the reference, less what the reference's own noise adds to it.
double relMse(const std::vector<glm::vec3>& image, const Reference& ref) {
    double sum = 0.0;
    for (size_t i = 0; i < image.size(); ++i)
        for (int c = 0; c < 3; ++c) {
            const double r = ref.mean[i][c], d = double(image[i][c]) - r;
            sum += (d * d - ref.variance[i][c]) / (r * r + 0.01);
        }
    return sum / double(image.size() * 3);
}

/// Least-squares slope of log(y) against log(x).
double logLogSlope(const std::vector<double>& x, const std::vector<double>& y) {
    double mx = 0, my = 0;
    for (size_t i = 0; i < x.size(); ++i) {
        mx += std::log(x[i]) / double(x.size());
        my += std::log(y[i]) / double(x.size());
    }
    double sxy = 0, sxx = 0;
    for (size_t i = 0; i < x.size(); ++i) {
        sxy += (std::log(x[i]) - mx) * (std::log(y[i]) - my);
        sxx += (std::log(x[i]) - mx) * (std::log(x[i]) - mx);
    }
    return sxy / sxx;
}

}  // namespace

TEST(StillConverge, UnderMotionTheOutputIsTheDenoisersBitForBit) {
    // (a) and (d): with the camera orbiting every frame restarts the mean, and the first frame of a mean is the
    // denoised image itself, so the graph renders what it rendered before it converged, to the bit.
    for (const auto& [file, denoised] : {std::pair<std::string, std::string>{"PathTracerSVGF.json", "SVGF.filtered"},
                                         {"PathTracerSVGFTAA.json", "TAA.colorOut"}}) {
        SCOPED_TRACE(file);
        const GraphDesc desc = loadGraph(graphPath(file));
        GraphRun converging(desc, CameraPathKind::Orbit, {denoised});
        GraphRun before(withoutAccumulate(desc), CameraPathKind::Orbit, {});
        for (int f = 0; f < 6; ++f) {
            converging.step();
            before.step();
            EXPECT_EQ(converging.stat("Accumulate", "frames"), 1.0) << "frame " << f;
            EXPECT_TRUE(test::sameBits(converging.field("Accumulate.dst"), converging.field(denoised)))
                << "frame " << f;
            EXPECT_TRUE(test::sameBits(converging.field("ToneMap.dst"), before.field("ToneMap.dst"))) << "frame " << f;
        }
    }
}

TEST(StillConverge, StillErrorFallsLikeOneOverFramesAndBelowTheDenoisers) {
    // (b) The reference is the limit of the graph's running mean (its path tracer at 4 x 256 spp, other seeds); its own
    // noise is taken out of every error. With the denoised image worth K frames, the blend's error is about
    // (K^2 e_D + (n-1) s2) / (n-1+K)^2 (blendDenoised): like 1 / n once n >> K. K = 4 here, so 16..256 frames are
    // well past it; the expected slope is -1 (-0.93 for the +K-1 offset over this range), accepted within
    // [-1.2, -0.8]. With the graph's own K the error must end below the denoiser's, which stays level.
    const Reference ref = referenceOf("PathTracerSVGF.json", 4, 256);
    const GraphDesc desc = loadGraph(graphPath("PathTracerSVGF.json"));
    const std::vector<uint64_t> checkpoints = {16, 32, 64, 128, 256};

    GraphRun fast(desc, CameraPathKind::Static, {});
    fast.graph->setParam("Accumulate", "denoisedFrames", 4.0, "test");
    std::vector<double> frames, errors;
    while (fast.frame < checkpoints.back()) {
        fast.step();
        if (std::find(checkpoints.begin(), checkpoints.end(), fast.frame) == checkpoints.end()) continue;
        ASSERT_EQ(fast.stat("Accumulate", "frames"), double(fast.frame));
        frames.push_back(double(fast.frame));
        errors.push_back(relMse(rgb(fast.field("Accumulate.dst")), ref));
    }
    for (size_t i = 0; i < errors.size(); ++i)
        RecordProperty("relmse_k4_" + std::to_string(int(frames[i])), std::to_string(errors[i]));
    const double slope = logLogSlope(frames, errors);
    EXPECT_GT(slope, -1.2) << "errors " << ::testing::PrintToString(errors);
    EXPECT_LT(slope, -0.8) << "errors " << ::testing::PrintToString(errors);

    GraphRun converging(desc, CameraPathKind::Static, {"SVGF.filtered"});
    GraphRun denoiserOnly(withoutAccumulate(desc), CameraPathKind::Static, {"SVGF.filtered"});
    double first = 0.0, denoiserAtEnd = 0.0, convergedAtEnd = 0.0;
    for (uint64_t f = 1; f <= checkpoints.back(); ++f) {
        converging.step();
        denoiserOnly.step();
        if (f == 1) first = relMse(rgb(converging.field("Accumulate.dst")), ref);
    }
    denoiserAtEnd = relMse(rgb(denoiserOnly.field("SVGF.filtered")), ref);
    convergedAtEnd = relMse(rgb(converging.field("Accumulate.dst")), ref);
    RecordProperty("relmse_denoiser_256", std::to_string(denoiserAtEnd));
    RecordProperty("relmse_graph_256", std::to_string(convergedAtEnd));
    RecordProperty("relmse_graph_1", std::to_string(first));
    EXPECT_LT(convergedAtEnd, 0.5 * denoiserAtEnd) << "denoiser " << denoiserAtEnd << ", converging " << convergedAtEnd;
    EXPECT_LT(convergedAtEnd, first);
}

TEST(StillConverge, ACameraMoveOrAParameterUpstreamRestartsFromTheDenoisedImage) {
    // (c) Each change shows in the very next frame: a mean of one frame, the denoised image to the bit.
    GraphRun r(loadGraph(graphPath("PathTracerSVGF.json")), CameraPathKind::Static, {"SVGF.filtered"});
    const auto expectRestart = [&](const std::string& what) {
        r.step();
        EXPECT_EQ(r.stat("Accumulate", "frames"), 1.0) << what;
        EXPECT_TRUE(test::sameBits(r.field("Accumulate.dst"), r.field("SVGF.filtered"))) << what;
        r.step();
        EXPECT_EQ(r.stat("Accumulate", "frames"), 2.0) << what << ": still again";
        EXPECT_FALSE(test::sameBits(r.field("Accumulate.dst"), r.field("SVGF.filtered"))) << what << ": still again";
    };
    const auto expectGoesOn = [&](const std::string& what) {
        const double before = r.stat("Accumulate", "frames");
        r.step();
        EXPECT_EQ(r.stat("Accumulate", "frames"), before + 1.0) << what;
    };
    for (int f = 0; f < 4; ++f) r.step();
    ASSERT_EQ(r.stat("Accumulate", "frames"), 4.0);

    r.graph->setParam("PathTracer", "maxBounces", 2, "test");
    expectRestart("PathTracer.maxBounces");
    r.graph->setParam("SVGF", "phiColor", 8.0, "test");  // the denoiser's image is part of the output too
    expectRestart("SVGF.phiColor");
    // As the viewer moves it: the pose takes effect at the next update, which keeps this one as the previous.
    const glm::mat4 current = r.scene->camera.world;
    r.scene->setCameraPose(glm::translate(current, glm::vec3(0.01f, 0.f, 0.f)));
    r.scene->camera.world = current;
    expectRestart("camera move");

    // What does not change the image the samples estimate goes on: a new seed or sample count, a pass downstream,
    // the accumulator's own blend, a value set again, and the animation clock of a still scene.
    r.graph->setParam("PathTracer", "seed", 7, "test");
    expectGoesOn("PathTracer.seed");
    r.graph->setParam("PathTracer", "samplesPerPixel", 2, "test");
    expectGoesOn("PathTracer.samplesPerPixel");
    r.graph->setParam("ToneMap", "operator", "reinhard", "test");
    expectGoesOn("ToneMap.operator");
    r.graph->setParam("Accumulate", "denoisedFrames", 16.0, "test");
    expectGoesOn("Accumulate.denoisedFrames");
    r.graph->setParam("PathTracer", "maxBounces", 2, "test");
    expectGoesOn("PathTracer.maxBounces set to its value");

    // Disabled, the accumulator passes the denoised image on: the graph as it was before it converged.
    r.graph->setParam("Accumulate", "enabled", false, "test");
    r.step();
    EXPECT_TRUE(test::sameBits(r.field("Accumulate.dst"), r.field("SVGF.filtered")));
}
