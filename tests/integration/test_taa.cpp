// TAAPass: exact pass-through of a constant image, energy kept on a jittered light (static and moving), convergence to
// the supersampled image of a jittered G-buffer,
// reprojection that follows motion (integer and fractional), clipping that bounds ghosting, history invalid and
// off-frame cases, non-finite input, the tiled path against the reference kernel (to a tolerance), determinism across
// thread counts, and parameter-independent reflection.
#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <functional>
#include <glm/glm.hpp>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "../../passes/TAA/TAAKernels.h"
#include "TestUtil.h"
#include "loom/Camera.h"
#include "loom/Graph.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"
#include "loom/Texture.h"

using namespace loom;

namespace {

using test::MotionSource;

PluginRegistry& registry() { return test::registryWithFunctionSource(); }

/// MotionSource -> TAA (mvec wired by name), one frame at a time.
struct Harness {
    explicit Harness(const nlohmann::json& params = nlohmann::json::object(), uint32_t width = 64, uint32_t height = 64)
        : graph(describe(params), registry()) {
        CompileOptions o;
        o.width = width;
        o.height = height;
        graph.compile(o);
        source = dynamic_cast<MotionSource*>(graph.pass("Source"));
    }
    static GraphDesc describe(const nlohmann::json& params) {
        nlohmann::json g = {{"loom_graph", 1},
                            {"name", "taa"},
                            {"passes",
                             {{{"name", "Source"}, {"type", "MotionSource"}},
                              {{"name", "TAA"}, {"type", "TAAPass"}, {"params", params}}}},
                            {"edges", nlohmann::json::array({nlohmann::json::array({"Source.color", "TAA.colorIn"})})},
                            {"outputs", {"TAA.colorOut"}}};
        return parseGraph(g.dump());
    }
    void run() {
        FrameInfo f;
        f.frameIndex = frame++;
        f.time = double(f.frameIndex) / 60.0;
        graph.execute(f);
    }
    void run(int n) {
        for (int i = 0; i < n; ++i) run();
    }
    const Texture& field(const std::string& name) const {
        const Texture* t = graph.fieldTexture("TAA." + name);
        if (!t) throw std::runtime_error("no texture for TAA." + name);
        return *t;
    }
    glm::vec4 out(uint32_t x, uint32_t y) const { return field("colorOut").view<glm::vec4>().at(x, y); }
    double stat(const std::string& name) const { return graph.lastStats().at("TAA").at(name); }

    RenderGraph graph;
    MotionSource* source = nullptr;
    uint64_t frame = 0;
};

/// A deterministic value in [0, 1) from three integers.
float hash01(uint64_t a, int64_t b, int64_t c) {
    uint64_t h = a * 0x9E3779B97F4A7C15ull ^ uint64_t(b) * 0xC2B2AE3D27D4EB4Full ^ uint64_t(c) * 0x165667B19E3779F9ull;
    h ^= h >> 29;
    h *= 0xBF58476D1CE4E5B9ull;
    h ^= h >> 32;
    return float(h >> 40) / float(1u << 24);
}

std::unique_ptr<Texture> copyOf(const Texture& t) {
    auto c = std::make_unique<Texture>(t.width(), t.height(), t.format());
    c->copyFrom(t);
    return c;
}

bool allFinite(const Texture& t) {
    for (uint32_t y = 0; y < t.height(); ++y)
        for (uint32_t x = 0; x < t.width(); ++x)
            for (uint32_t c = 0; c < 4; ++c)
                if (!std::isfinite(t.texel(x, y, c))) return false;
    return true;
}

/// A textured image of pattern coordinates (u, v) with per-frame noise: what a jittered renderer produces.
// noipa: one compiled body (no inlined or constant-propagated copies that could contract differently), so the
// tests can recompute exactly what the source wrote.
[[gnu::noipa]] glm::vec4 noisyPattern(uint64_t frame, int64_t u, int64_t v) {
    const float base = 0.5f + 0.4f * std::sin(0.37f * float(u)) * std::cos(0.23f * float(v));
    const float n = 0.1f * (hash01(frame, u, v) - 0.5f);
    return glm::vec4(base + n, 0.5f * base + n, 1.f - base, 1.f);
}

/// A small light (a disk whose radiance rises from 10 to 100 across it, and a thin bar of 40) on a 0.1 background,
/// point-sampled once per pixel at the pixel's centre plus the camera's 16-sample Halton jitter of frame f, the
/// content displaced by `shift` pixels a frame: what a path tracer's emitter looks like to TAA.
[[gnu::noipa]] glm::vec4 jitteredLight(uint64_t f, uint32_t x, uint32_t y, glm::vec2 shift) {
    const glm::vec2 j = Camera::jitterSample(JitterPattern::Halton, 16, f);
    const glm::vec2 p = glm::vec2(float(x), float(y)) + 0.5f + j - shift * float(f);
    const glm::vec2 d = p - glm::vec2(30.3f, 28.7f);
    float v = 0.1f;
    if (d.x * d.x + d.y * d.y < 6.2f * 6.2f)
        v = 10.f + 90.f * (d.x + 6.2f) / 12.4f;
    else if (p.x > 12.4f && p.x < 26.6f && p.y > 44.2f && p.y < 46.5f)
        v = 40.f;
    return glm::vec4(v, 0.8f * v, 0.6f * v, 1.f);
}

/// Luminance (YCoCg luma) summed over the frame, in double.
double lumaSum(const Texture& t) {
    const auto v = t.view<glm::vec4>();
    double s = 0.0;
    for (uint32_t y = 0; y < v.height; ++y)
        for (uint32_t x = 0; x < v.width; ++x) s += double(taa::toYCoCg(v.at(x, y)).x);
    return s;
}

/// The energy TAA keeps of jitteredLight (moving by `shift` pixels a frame, with exact motion vectors): the ratio of
/// the output's luminance to the input's, both summed over the frame and over the last 16 frames (one period of the
/// jitter, so the input's sum is its box-filtered mean over the jitter positions) after `frames` frames.
double energyRatio(const nlohmann::json& params, glm::vec2 shift, int frames) {
    Harness h(params);
    h.source->color = [shift](uint64_t f, uint32_t x, uint32_t y) { return jitteredLight(f, x, y, shift); };
    h.source->motion = [shift](uint64_t, uint32_t, uint32_t) { return -shift / 64.f; };
    double in = 0.0, out = 0.0;
    for (int f = 0; f < frames; ++f) {
        h.run();
        if (f < frames - 16) continue;
        out += lumaSum(h.field("colorOut"));
        for (uint32_t y = 0; y < 64; ++y)
            for (uint32_t x = 0; x < 64; ++x) in += double(taa::toYCoCg(h.source->color(h.frame - 1, x, y)).x);
    }
    return out / in;
}

/// Restricts Highway's run-time dispatch to `targets` (0: what the CPU has) for its scope, however the scope ends (a
/// failed ASSERT returns from the test).
struct DispatchTargets {
    explicit DispatchTargets(int64_t targets) { hwy::SetSupportedTargetsForTest(targets); }
    ~DispatchTargets() { hwy::SetSupportedTargetsForTest(0); }
    DispatchTargets(const DispatchTargets&) = delete;
    DispatchTargets& operator=(const DispatchTargets&) = delete;
};

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Static input

TEST(TAAPass, ConstantImageWithZeroMotionPassesThroughExactly) {
    for (const auto& params : {nlohmann::json::object(), nlohmann::json{{"antiFlicker", true}, {"hdrCompress", true}},
                               nlohmann::json{{"reference", true}}})
        for (const glm::vec4 c : {glm::vec4(0.3f, 0.6f, 0.9f, 1.f), glm::vec4(7.25f, 0.01f, 123.f, 0.5f),
                                  glm::vec4(1e30f, 2e30f, 0.f, 1.f)}) {
            SCOPED_TRACE(params.dump());
            Harness h(params);
            h.source->color = [&](uint64_t, uint32_t, uint32_t) { return c; };
            for (int f = 0; f < 6; ++f) {
                h.run();
                for (uint32_t y = 0; y < 64; ++y)
                    for (uint32_t x = 0; x < 64; ++x) ASSERT_EQ(h.out(x, y), c) << x << "," << y << " frame " << f;
            }
            EXPECT_EQ(h.stat("clipped"), 0);
            EXPECT_EQ(h.stat("noHistory"), 0);
        }
}

// A light's edges under Halton jitter: an edge pixel sees the light in some jitter positions and not in others. The
// converged output must keep the light's energy, i.e. TAA may move light only as the reference's own pixel filter
// (the box over the jitter positions) does: summed over the frame and a jitter period, output = input within 1 %,
// for the tiled path and the reference kernel. The optional luminance weightings (antiFlicker, hdrCompress) average
// with weights that fall with the sample's value, so they must lose energy here: that shows what the property
// measures, and what those options cost.
TEST(TAAPass, KeepsTheEnergyOfAStaticJitteredLight) {
    const glm::vec2 still(0.f);
    for (bool reference : {false, true}) {
        const double r = energyRatio(nlohmann::json{{"reference", reference}}, still, 96);
        std::printf("%s: output / input energy %.5f\n", reference ? "reference" : "tiled", r);
        EXPECT_NEAR(r, 1.0, 0.01) << (reference ? "reference" : "tiled");
    }
    const double sigma10 = energyRatio(nlohmann::json{{"sigma", 10.f}}, still, 96);
    std::printf("without clipping (sigma 10): %.5f\n", sigma10);
    EXPECT_NEAR(sigma10, 1.0, 1e-3) << "a linear moving average of a periodic input keeps its mean";
    for (const char* option : {"antiFlicker", "hdrCompress"}) {
        const double r = energyRatio(nlohmann::json{{option, true}}, still, 96);
        std::printf("with %s: %.5f\n", option, r);
        EXPECT_LT(r, 0.95) << option << " is expected to darken the light's edges";
    }
}

// The same light moving by (0.37, 0.11) pixels a frame with exact motion vectors: every frame resamples the history
// with Catmull-Rom, which keeps energy (its weights sum to one over any shift), but the resampled edge is softer than
// the point-sampled current frame, and the part of it that reaches pixels whose neighbourhood is flat, or lies outside
// the clip box, is dropped: measured 1.2 % here. The weightings lose far more.
TEST(TAAPass, KeepsTheEnergyOfAMovingJitteredLight) {
    const glm::vec2 shift(0.37f, 0.11f);
    const double r = energyRatio(nlohmann::json::object(), shift, 40);
    const double weighted = energyRatio(nlohmann::json{{"antiFlicker", true}, {"hdrCompress", true}}, shift, 40);
    std::printf("moving light: output / input energy %.5f; with antiFlicker and hdrCompress %.5f\n", r, weighted);
    EXPECT_NEAR(r, 1.0, 0.025);
    EXPECT_LT(weighted, r - 0.05);
}

TEST(TAAPass, InvalidHistoryOrOffFrameReprojectionGivesTheCurrentColour) {
    Harness h;
    h.source->color = [](uint64_t f, uint32_t x, uint32_t y) { return noisyPattern(f, x, y); };
    h.run();  // first frame: no history
    EXPECT_EQ(h.stat("noHistory"), 64 * 64);
    for (uint32_t y = 0; y < 64; y += 7)
        for (uint32_t x = 0; x < 64; x += 5) ASSERT_EQ(h.out(x, y), noisyPattern(0, x, y)) << x << "," << y;
    h.run(3);
    EXPECT_EQ(h.stat("noHistory"), 0);
    h.graph.resetHistory();
    h.run();
    EXPECT_EQ(h.stat("noHistory"), 64 * 64);
    EXPECT_EQ(h.out(10, 10), noisyPattern(4, 10, 10));

    // Everything moves 3 pixels left: the 3 rightmost columns come from outside the frame.
    h.source->motion = [](uint64_t, uint32_t, uint32_t) { return glm::vec2(3.f / 64.f, 0.f); };
    h.run();
    EXPECT_EQ(h.stat("noHistory"), 3 * 64);
    for (uint32_t y = 0; y < 64; ++y) {
        EXPECT_EQ(h.out(63, y), noisyPattern(5, 63, y));
        EXPECT_EQ(h.out(61, y), noisyPattern(5, 61, y));
        EXPECT_NE(h.out(60, y), noisyPattern(5, 60, y));
    }
}

// Motion vectors far beyond the frame, integer ones (which take the vector path's contiguous load when in the frame)
// and the largest floats of either sign: no history anywhere, the output is the current colour, for the tiled path
// and the reference kernel alike.
TEST(TAAPass, HugeMotionVectorsGiveTheCurrentColour) {
    for (const bool reference : {false, true}) {
        for (const float m : {4096.f, -4096.f, 1e30f, -1e30f, std::numeric_limits<float>::max()}) {
            Harness h(nlohmann::json{{"reference", reference}});
            h.source->color = [](uint64_t f, uint32_t x, uint32_t y) { return noisyPattern(f, x, y); };
            h.run();
            h.source->motion = [m](uint64_t, uint32_t, uint32_t) { return glm::vec2(m, m); };
            h.run();
            EXPECT_EQ(h.stat("noHistory"), 64 * 64) << m;
            for (uint32_t y = 0; y < 64; y += 3)
                for (uint32_t x = 0; x < 64; ++x) ASSERT_EQ(h.out(x, y), noisyPattern(1, x, y)) << m << " " << x;
        }
    }
}

// A static scene rendered with Halton jitter: TAA converges to the supersampled image (the mean of the jittered
// frames, from AccumulatePass) far more closely than any single frame is to it.
TEST(TAAPass, ConvergesToTheSupersampledImageOfAJitteredGBuffer) {
    auto scene = Scene::load(test::dataScene("cornell_box.gltf"));
    scene->camera.jitterPattern = JitterPattern::Halton;
    const uint32_t W = 96, H = 96;
    nlohmann::json g = {{"loom_graph", 1},
                        {"name", "taa_gbuffer"},
                        {"passes",
                         {{{"name", "GBuffer"}, {"type", "GBufferRT"}},
                          {{"name", "TAA"}, {"type", "TAAPass"}},
                          {{"name", "Accumulate"}, {"type", "AccumulatePass"}}}},
                        {"edges", nlohmann::json::array({nlohmann::json::array({"GBuffer.albedo", "TAA.colorIn"}),
                                                         nlohmann::json::array({"GBuffer.albedo", "Accumulate.src"})})},
                        {"outputs", {"TAA.colorOut", "Accumulate.dst", "GBuffer.albedo"}}};
    RenderGraph graph(parseGraph(g.dump()), test::pluginRegistry());
    graph.setScene(scene);
    CompileOptions o;
    o.width = W;
    o.height = H;
    graph.compile(o);

    const int frames = 64;  // 4 periods of the 16-sample Halton pattern
    std::vector<std::unique_ptr<Texture>> singles;
    for (int f = 0; f < frames; ++f) {
        const double time = 0.0;  // static
        scene->update(time);
        scene->camera.aspect = float(W) / float(H);
        scene->camera.beginFrame(uint64_t(f));
        graph.execute(FrameInfo{uint64_t(f), time, scene.get(), &scene->camera});
        if (f >= frames - 16) singles.push_back(copyOf(*graph.fieldTexture("GBuffer.albedo")));
    }
    const auto reference = graph.fieldTexture("Accumulate.dst")->view<glm::vec4>();
    const auto taa = graph.fieldTexture("TAA.colorOut")->view<glm::vec4>();
    auto error = [&](const auto& img) {
        double e = 0.0;
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x) {
                const glm::vec4 d = img.at(x, y) - reference.at(x, y);
                e += std::fabs(d.x) + std::fabs(d.y) + std::fabs(d.z);
            }
        return e / double(W * H);
    };
    double singleError = 0.0;
    for (const auto& s : singles) singleError += error(s->view<glm::vec4>()) / double(singles.size());
    const double taaError = error(taa);
    std::printf("mean abs error vs the 64-frame mean: single jittered frame %.5f, TAA %.5f (ratio %.3f)\n", singleError,
                taaError, taaError / singleError);
    EXPECT_GT(singleError, 1e-3) << "the jitter should change the image";
    EXPECT_LT(taaError, 0.4 * singleError);
}

// ---------------------------------------------------------------------------------------------------------------
// Motion

// Content moves by (2, 1) pixels per frame with exact motion vectors: the output at a moving pixel equals the
// output of the same content held still, bit for bit, wherever the pixel's history stayed inside the frame.
TEST(TAAPass, HistoryFollowsIntegerMotionExactly) {
    const int dx = 2, dy = 1;
    Harness moving, still;
    moving.source->color = [&](uint64_t f, uint32_t x, uint32_t y) {
        return noisyPattern(f, int64_t(x) - dx * int64_t(f), int64_t(y) - dy * int64_t(f));
    };
    // uvPrev - uvCur: the content at x was at x - dx last frame.
    moving.source->motion = [&](uint64_t, uint32_t, uint32_t) { return glm::vec2(-dx / 64.f, -dy / 64.f); };
    still.source->color = [&](uint64_t f, uint32_t x, uint32_t y) { return noisyPattern(f, x, y); };
    const int frames = 12;
    int compared = 0;
    for (int f = 0; f < frames; ++f) {
        moving.run();
        still.run();
        // Pixel (u, v) of the still image is at (u + dx f, v + dy f) in the moving one; both see the same 3x3
        // neighbourhood away from the borders, over the whole history chain.
        for (int v = 1; v + 1 < 64; ++v)
            for (int u = 1; u + 1 < 64; ++u) {
                const int x = u + dx * f, y = v + dy * f;
                if (x + 1 >= 64 || y + 1 >= 64) continue;
                ASSERT_EQ(moving.out(uint32_t(x), uint32_t(y)), still.out(uint32_t(u), uint32_t(v)))
                    << "frame " << f << " still pixel " << u << "," << v;
                ++compared;
            }
    }
    EXPECT_GT(compared, 10000);
    EXPECT_GT(still.stat("clipped"), 0) << "the noise should make clipping matter";
}

// A linear ramp moving half a pixel per frame: Catmull-Rom reproduces linear functions, so the reprojected
// history lands on the current value and the output is the current ramp. Zero motion vectors leave a lag.
TEST(TAAPass, FractionalMotionIsReprojectedWithTheBicubicFilter) {
    auto ramp = [](uint64_t f, uint32_t x, uint32_t y) {
        const float u = float(x) - 0.5f * float(f);
        return glm::vec4(0.01f * u + 0.2f, 0.005f * float(y) + 0.3f, 0.5f - 0.004f * u, 1.f);
    };
    for (bool withMotion : {true, false}) {
        SCOPED_TRACE(withMotion ? "exact mvec" : "zero mvec");
        Harness h(nlohmann::json{{"sigma", 10.f}});  // a wide box: the test is about reprojection, not clipping
        h.source->color = ramp;
        if (withMotion) h.source->motion = [](uint64_t, uint32_t, uint32_t) { return glm::vec2(-0.5f / 64.f, 0.f); };
        h.run(12);
        // Content enters at the left edge with clamped (wrong) history, which then travels right with it at half a
        // pixel per frame and spreads by the filter's support: after 12 frames x >= 24 is clear of it.
        double maxError = 0.0;
        for (uint32_t y = 2; y < 62; ++y)
            for (uint32_t x = 24; x < 56; ++x)
                maxError = std::max(maxError, double(std::fabs(h.out(x, y).x - ramp(11, x, y).x)));
        if (withMotion)
            EXPECT_LT(maxError, 2e-5);
        else
            EXPECT_GT(maxError, 1e-3) << "without motion vectors the history lags";
    }
}

TEST(TAAPass, MotionIsDilatedToTheLongestVectorOfTheNeighbourhood) {
    taa::ClampedImage<glm::vec2> img;
    glm::vec2 data[9] = {glm::vec2(0.f),        glm::vec2(0.1f, 0.f), glm::vec2(0.f),
                         glm::vec2(0.f, -0.2f), glm::vec2(0.f),       glm::vec2(0.f),
                         glm::vec2(0.f),        glm::vec2(0.2f, 0.f), glm::vec2(0.f)};
    img.data = data;
    img.width = img.height = 3;
    img.rowPitch = 3 * sizeof(glm::vec2);
    glm::vec2 m;
    ASSERT_TRUE(taa::dilatedMotion(img, 1, 1, m));
    EXPECT_EQ(m, glm::vec2(0.f, -0.2f)) << "the first of the two longest, in row-major order";
    data[3] = glm::vec2(std::numeric_limits<float>::quiet_NaN());
    ASSERT_TRUE(taa::dilatedMotion(img, 1, 1, m));
    EXPECT_EQ(m, glm::vec2(0.2f, 0.f)) << "non-finite vectors are ignored";
}

// ---------------------------------------------------------------------------------------------------------------
// Clipping and bad input

TEST(TAAPass, ClippingBoundsGhostingAfterASuddenChange) {
    // A constant change: the box collapses to the new value and the old one is gone in one frame.
    {
        Harness h;
        h.source->color = [](uint64_t, uint32_t, uint32_t) { return glm::vec4(0.1f, 0.1f, 0.1f, 1.f); };
        h.run(20);
        const glm::vec4 after(0.8f, 0.7f, 0.6f, 1.f);
        h.source->color = [&](uint64_t, uint32_t, uint32_t) { return after; };
        // Plain blending would give 0.9 * 0.1 + 0.1 * 0.8 = 0.17 now and still 0.43 after 5 frames.
        for (int f = 0; f < 3; ++f) {
            h.run();
            for (uint32_t y = 0; y < 64; ++y)
                for (uint32_t x = 0; x < 64; ++x)
                    for (int c = 0; c < 4; ++c) ASSERT_NEAR(h.out(x, y)[c], after[c], 1e-6) << x << "," << y;
        }
    }
    // A change to a texture: the output at once lies in the new 3x3 neighbourhood's YCoCg min / max box (the
    // clipped history and the current colour are both in it, and the blend is convex).
    {
        Harness h;
        h.source->color = [](uint64_t, uint32_t, uint32_t) { return glm::vec4(0.1f, 0.1f, 0.1f, 1.f); };
        h.run(20);
        auto after = [](uint64_t f, uint32_t x, uint32_t y) {
            return glm::vec4(0.6f + 0.3f * hash01(f, x, y), 0.7f, 0.8f - 0.2f * hash01(f + 7, x, y), 1.f);
        };
        h.source->color = after;
        h.run();
        const uint64_t f = h.frame - 1;
        for (int y = 0; y < 64; ++y)
            for (int x = 0; x < 64; ++x) {
                glm::vec4 lo(1e30f), hi(-1e30f);
                for (int dy = -1; dy <= 1; ++dy)
                    for (int dx = -1; dx <= 1; ++dx) {
                        const glm::vec4 v = taa::toYCoCg(
                            after(f, uint32_t(std::clamp(x + dx, 0, 63)), uint32_t(std::clamp(y + dy, 0, 63))));
                        lo = glm::min(lo, v);
                        hi = glm::max(hi, v);
                    }
                const glm::vec4 o = taa::toYCoCg(h.out(uint32_t(x), uint32_t(y)));
                for (int c = 0; c < 4; ++c) {
                    ASSERT_GE(o[c], lo[c] - 1e-6f) << x << "," << y << " channel " << c;
                    ASSERT_LE(o[c], hi[c] + 1e-6f) << x << "," << y << " channel " << c;
                }
            }
    }
}

// A 3x3 neighbourhood of one colour pins any history to that colour (the clip box is a point), so the resolve is
// the current colour, exactly and without reading the history; such pixels do not count as clipped. A bright
// square moves across a grey background with zero motion vectors, so the history under its trail differs.
TEST(TAAPass, AFlatNeighbourhoodResolvesToTheCurrentColourExactly) {
    for (bool reference : {false, true}) {
        Harness h(nlohmann::json{{"reference", reference}}, 70, 40);  // partial tiles
        const glm::vec4 grey(0.3f, 0.25f, 0.2f, 1.f), bright(6.f, 5.f, 4.f, 1.f);
        auto inSquare = [](uint64_t f, int x, int y) {
            const int x0 = 5 + 3 * int(f);
            return x >= x0 && x < x0 + 8 && y >= 12 && y < 20;
        };
        h.source->color = [&](uint64_t f, uint32_t x, uint32_t y) {
            return inSquare(f, int(x), int(y)) ? bright : grey;
        };
        for (int f = 0; f < 12; ++f) {
            h.run();
            const uint64_t frame = h.frame - 1;
            uint64_t flat = 0;
            for (int y = 0; y < 40; ++y)
                for (int x = 0; x < 70; ++x) {
                    bool one = true;  // every neighbour (edges repeated) grey
                    for (int dy = -1; dy <= 1; ++dy)
                        for (int dx = -1; dx <= 1; ++dx)
                            one = one && !inSquare(frame, std::clamp(x + dx, 0, 69), std::clamp(y + dy, 0, 39));
                    if (!one) continue;
                    ++flat;
                    ASSERT_EQ(h.out(uint32_t(x), uint32_t(y)), grey)
                        << "reference " << reference << " frame " << f << " pixel " << x << "," << y;
                }
            EXPECT_LE(h.stat("clipped"), double(70 * 40 - flat)) << "reference " << reference << " frame " << f;
        }
        // The trail really held other history: the last frame's square left it 33 columns back.
        EXPECT_GT(h.stat("clipped"), 0.0);
    }
}

// Tiles of one colour (a black sky) skip the neighbourhood statistics; they still follow the motion, so the pixels
// whose history comes from outside the frame are counted as before, and a single pixel of another colour brings the
// statistics back for its tile: output, history and counts as the reference kernel's.
TEST(TAAPass, OneColourTilesSkipTheStatisticsButNotTheMotion) {
    const uint32_t W = 300, H = 40;  // three tile columns, the last partial
    const glm::vec4 sky(0.02f, 0.03f, 0.05f, 1.f), odd(0.9f, 0.1f, 0.1f, 1.f);
    std::unique_ptr<Texture> out[2], history[2];
    double noHistory[2], clipped[2];
    for (int run = 0; run < 2; ++run) {
        Harness h(nlohmann::json{{"reference", run == 1}}, W, H);
        h.source->color = [&](uint64_t f, uint32_t x, uint32_t y) { return f >= 2 && x == 200 && y == 7 ? odd : sky; };
        // Everything moves 5 pixels left from frame 3 on: the 5 rightmost columns come from outside the frame.
        h.source->motion = [](uint64_t f, uint32_t, uint32_t) { return glm::vec2(f >= 3 ? 5.f / 300.f : 0.f, 0.f); };
        h.run(5);
        out[run] = copyOf(h.field("colorOut"));
        history[run] = copyOf(h.field("colorHistory"));
        noHistory[run] = h.stat("noHistory");
        clipped[run] = h.stat("clipped");
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x) {
                const bool nearOdd = x + 1 >= 200 && x <= 201 && y + 1 >= 7 && y <= 8;
                if (!nearOdd) {
                    ASSERT_EQ(h.out(x, y), sky) << "run " << run << " pixel " << x << "," << y;
                }
            }
    }
    EXPECT_EQ(noHistory[0], 5.0 * H);
    EXPECT_EQ(noHistory[0], noHistory[1]);
    EXPECT_EQ(clipped[0], clipped[1]);
    const auto fast = out[0]->view<glm::vec4>(), reference = out[1]->view<glm::vec4>();
    const auto fastHistory = history[0]->view<glm::vec4>(), referenceHistory = history[1]->view<glm::vec4>();
    for (uint32_t y = 0; y < H; ++y)
        for (uint32_t x = 0; x < W; ++x)
            for (int c = 0; c < 4; ++c) {
                ASSERT_NEAR(fast.at(x, y)[c], reference.at(x, y)[c], 1e-4f * std::max(1.f, reference.at(x, y)[c]))
                    << x << "," << y;
                ASSERT_NEAR(fastHistory.at(x, y)[c], referenceHistory.at(x, y)[c], 1e-6f) << x << "," << y;
            }
    // The odd pixel went through the statistics and the history: a blend, neither its own colour nor the sky.
    EXPECT_NE(fast.at(200, 7), odd);
    EXPECT_NE(fast.at(200, 7), sky);
}

// One-colour tiles whose motion keeps every pixel in the frame skip even the per-pixel resolve; the results and the
// counts must be what the reference kernel gives: the frame without history, motion out of the frame at one edge,
// and a region that compares equal but differs in its bits (-0 among +0), whose pixels keep their own bits.
TEST(TAAPass, OneColourTilesResolveToTheirInputBitForBit) {
    const uint32_t W = 300, H = 40;
    const glm::vec4 sky(0.f, 0.f, 0.f, 1.f);
    struct Run {
        const char* name;
        bool reference;
        int64_t target;  // 0: the best the CPU has
    };
    for (const Run run : {Run{"reference", true, 0}, Run{"tiled, AVX2", false, HWY_AVX2}, Run{"tiled", false, 0}}) {
        if (run.target && (hwy::SupportedTargets() & run.target) == 0) continue;
        SCOPED_TRACE(run.name);
        const DispatchTargets dispatch(run.target);
        Harness h(nlohmann::json{{"reference", run.reference}}, W, H);
        h.source->color = [&](uint64_t, uint32_t x, uint32_t y) {
            return x == 20 && y == 30 ? glm::vec4(-0.f, 0.f, 0.f, 1.f) : sky;
        };
        // Down by 3 pixels a frame: the top 3 rows come from outside the frame once there is history.
        h.source->motion = [](uint64_t, uint32_t, uint32_t) { return glm::vec2(0.f, -3.f / 40.f); };
        h.run();
        EXPECT_EQ(h.stat("noHistory"), double(W * H)) << "the first frame has no history";
        h.run(2);
        EXPECT_EQ(h.stat("noHistory"), 3.0 * W);
        EXPECT_EQ(h.stat("clipped"), 0.0);
        const auto out = h.field("colorOut").view<glm::vec4>();
        const auto history = h.field("colorHistory").view<glm::vec4>();
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x) {
                const glm::vec4 input = h.source->color(h.frame - 1, x, y);
                ASSERT_EQ(std::memcmp(&out.at(x, y), &input, sizeof(glm::vec4)), 0) << x << "," << y;
                ASSERT_EQ(std::memcmp(&history.at(x, y), &input, sizeof(glm::vec4)), 0) << x << "," << y;
            }
        EXPECT_TRUE(std::signbit(out.at(20, 30).x));
    }
}

TEST(TAAPass, NonFiniteInputNeverReachesOutputOrHistory) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    for (bool reference : {false, true}) {
        SCOPED_TRACE(reference ? "reference" : "tiled");
        Harness h(nlohmann::json{{"reference", reference}});
        h.source->color = [](uint64_t f, uint32_t x, uint32_t y) { return noisyPattern(f, x, y); };
        h.source->motion = [](uint64_t, uint32_t, uint32_t) { return glm::vec2(0.3f / 64.f, -0.2f / 64.f); };
        h.run(5);
        h.source->color = [&](uint64_t f, uint32_t x, uint32_t y) {
            if (x == 20 && y == 20) return glm::vec4(nan);
            if (x == 21 && y == 20) return glm::vec4(inf, 0.f, 0.f, 1.f);
            if (x == 40 && y == 33) return glm::vec4(0.f, -inf, 0.f, 1.f);
            if (x >= 48 && y >= 48) return glm::vec4(nan);  // a whole region with no finite neighbour
            return noisyPattern(f, x, y);
        };
        h.source->motion = [&](uint64_t, uint32_t x, uint32_t y) {
            return x == 5 && y == 5 ? glm::vec2(nan) : glm::vec2(0.3f / 64.f, -0.2f / 64.f);
        };
        h.run();
        EXPECT_EQ(h.stat("nonFinite"), 3 + 16 * 16);
        EXPECT_TRUE(allFinite(h.field("colorOut")));
        EXPECT_TRUE(allFinite(h.field("colorHistory")));
        EXPECT_EQ(h.out(60, 60), glm::vec4(0.f)) << "no finite neighbour: 0";
        // The replaced pixel is within the range of its neighbours.
        EXPECT_GT(h.out(20, 20).x, 0.f);
        EXPECT_LT(h.out(20, 20).x, 1.f);
        // Clean input again: the next frames are finite and the NaN spot is indistinguishable from its surroundings.
        h.source->color = [](uint64_t f, uint32_t x, uint32_t y) { return noisyPattern(f, x, y); };
        h.source->motion = [](uint64_t, uint32_t, uint32_t) { return glm::vec2(0.f); };
        h.run();
        EXPECT_EQ(h.stat("nonFinite"), 0);
        EXPECT_TRUE(allFinite(h.field("colorOut")));
        EXPECT_TRUE(allFinite(h.field("colorHistory")));
        EXPECT_NEAR(h.out(20, 20).x, noisyPattern(h.frame - 1, 20, 20).x, 0.3);
    }
}

TEST(TAAPass, HugeInputsStayFinite) {
    const float huge = std::numeric_limits<float>::max();
    for (const auto& params : {nlohmann::json::object(), nlohmann::json{{"antiFlicker", true}, {"hdrCompress", true}},
                               nlohmann::json{{"reference", true}}}) {
        SCOPED_TRACE(params.dump());
        Harness h(params);
        h.source->color = [&](uint64_t f, uint32_t x, uint32_t y) {
            return (x + y + f) % 3 == 0 ? glm::vec4(huge, -huge, huge, 1.f) : glm::vec4(1.f);
        };
        h.source->motion = [](uint64_t, uint32_t, uint32_t) { return glm::vec2(0.25f / 64.f, 0.f); };
        for (int f = 0; f < 4; ++f) {
            h.run();
            ASSERT_TRUE(allFinite(h.field("colorOut"))) << f;
            ASSERT_TRUE(allFinite(h.field("colorHistory"))) << f;
        }
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Implementation checks

// The vector path uses FMA and refined hardware estimates of sqrt and 1/x where the reference divides, so the two
// agree to a tolerance, not to the bit: within 1e-4 of max(1, |value|) per channel after 8 frames of feedback
// (values up to 3, partial tiles, frame edges, clipping, dilation at a motion edge, a NaN tile). Returns the tiled
// path's vectorLanes stat.
namespace {
double tiledPathAgainstReference(uint32_t W, uint32_t H) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    double lanes = -1.0;
    for (bool weighted : {true, false}) {
        SCOPED_TRACE(weighted ? "anti-flicker, HDR compression" : "plain blend");
        std::unique_ptr<Texture> results[2];
        double clipped[2];
        for (int run = 0; run < 2; ++run) {
            Harness h(
                nlohmann::json{
                    {"reference", run == 1}, {"sigma", 1.25f}, {"antiFlicker", weighted}, {"hdrCompress", weighted}},
                W, H);
            h.source->color = [&](uint64_t f, uint32_t x, uint32_t y) {
                if (f == 3 && x == 50 && y == 9) return glm::vec4(nan);
                return noisyPattern(f, x, y) * 3.f;
            };
            h.source->motion = [&](uint64_t f, uint32_t x, uint32_t y) {
                // Varying, fractional motion: an edge where the dilation matters. Below row 40, whole-pixel motion
                // (zero on every other frame, a pan of (-3, 2) pixels on the others; a run of a vector's pixels on
                // one row reads its history texels directly), which must agree with the filter too.
                if (y >= 40) return f % 2 ? glm::vec2(-3.f / float(W), 2.f / float(H)) : glm::vec2(0.f);
                return x > 40 && x < 60 ? glm::vec2(-1.37f / float(W), 0.61f / float(H))
                                        : glm::vec2(0.11f / float(W), float(f % 2) / float(H));
            };
            h.run(8);
            results[run] = copyOf(h.field("colorOut"));
            clipped[run] = h.stat("clipped");
            if (run == 0) lanes = h.stat("vectorLanes");
        }
        const auto fast = results[0]->view<glm::vec4>(), reference = results[1]->view<glm::vec4>();
        double maxError = 0.0;
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x)
                for (int c = 0; c < 4; ++c) {
                    const double r = reference.at(x, y)[c];
                    const double e = std::fabs(double(fast.at(x, y)[c]) - r) / std::max(1.0, std::fabs(r));
                    EXPECT_LE(e, 1e-4) << x << "," << y << " channel " << c;
                    if (e > 1e-4) return lanes;
                    maxError = std::max(maxError, e);
                }
        std::printf("%ux%u, %g lanes: tiled path against the reference kernel: max error %.3g\n", W, H, lanes,
                    maxError);
        EXPECT_GT(clipped[1], 0.1 * W * H) << "clipping should be exercised";
        EXPECT_NEAR(clipped[0], clipped[1], 0.01 * clipped[1]) << "the same pixels are clipped, but for ties";
    }
    return lanes;
}
}  // namespace

TEST(TAAPass, TiledPathAgreesWithTheReferenceKernel) {
    tiledPathAgainstReference(100, 70);  // partial tiles
}

// The tiled path is compiled for AVX2 and AVX-512 and dispatched at run time: each target the CPU has agrees with the
// reference kernel, on a frame of several tiles whose last column and row are partial and whose widths are not whole
// vectors (1000 = 7 x 128 + 104, 104 = 6 x 16 + 8).
TEST(TAAPass, TiledPathAgreesWithTheReferenceKernelOnEveryTarget) {
    struct Target {
        int64_t bit;
        double lanes;
    };
    int tested = 0;
    for (const Target t : {Target{HWY_AVX2, 8}, Target{HWY_AVX3, 16}}) {
        if ((hwy::SupportedTargets() & t.bit) == 0) continue;
        SCOPED_TRACE(hwy::TargetName(t.bit));
        double lanes = 0.0;
        {
            const DispatchTargets dispatch(t.bit);
            lanes = tiledPathAgainstReference(1000, 37);
        }
        EXPECT_EQ(lanes, t.lanes) << "the dispatch should follow the supported targets";
        ++tested;
    }
    EXPECT_GE(tested, 1);
}

TEST(TAAPass, IdenticalResultsForAnyThreadCount) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    std::unique_ptr<Texture> results[3][2];
    double clipped[3];
    for (int run = 0; run < 3; ++run) {
        ThreadLimit limit(unsigned(run + 1));
        Harness h(nlohmann::json::object(), 128, 96);
        h.source->color = [&](uint64_t f, uint32_t x, uint32_t y) {
            if (hash01(f, x + 1000, y) < 0.002f) return glm::vec4(nan);
            return noisyPattern(f, int64_t(x) - int64_t(f), y);
        };
        h.source->motion = [](uint64_t, uint32_t x, uint32_t) {
            return glm::vec2(x < 64 ? -1.f / 128.f : -0.4f / 128.f, 0.f);
        };
        h.run(10);
        clipped[run] = h.stat("clipped");
        results[run][0] = copyOf(h.field("colorOut"));
        results[run][1] = copyOf(h.field("colorHistory"));
    }
    for (int run = 1; run < 3; ++run) {
        EXPECT_EQ(clipped[0], clipped[run]) << run + 1 << " threads";
        EXPECT_TRUE(results[0][0]->samePixels(*results[run][0])) << run + 1 << " threads";
        EXPECT_TRUE(results[0][1]->samePixels(*results[run][1])) << run + 1 << " threads";
    }
}

TEST(TAAPass, HistoryIsAGraphFieldThatCanBeObserved) {
    {
        Harness h;  // hdrCompress off, the default
        h.source->color = [](uint64_t f, uint32_t x, uint32_t y) { return noisyPattern(f, x, y); };
        h.run(3);
        // This frame's history side is this frame's output.
        EXPECT_TRUE(h.field("colorHistory").samePixels(h.field("colorOut")));
    }
    // With hdrCompress the history holds the output compressed: expanded, it is the output.
    Harness h(nlohmann::json{{"hdrCompress", true}});
    h.source->color = [](uint64_t f, uint32_t x, uint32_t y) { return 20.f * noisyPattern(f, x, y); };
    h.run(3);
    const auto hist = h.field("colorHistory").view<glm::vec4>(), out = h.field("colorOut").view<glm::vec4>();
    for (uint32_t y = 0; y < out.height; ++y)
        for (uint32_t x = 0; x < out.width; ++x) {
            const glm::vec4 e = taa::expandColor(hist.at(x, y)), o = out.at(x, y);
            for (int c = 0; c < 4; ++c)
                ASSERT_NEAR(e[c], o[c], 1e-5f * std::max(1.f, std::fabs(o[c]))) << x << "," << y;
        }
}

// A bright light next to a dark surface under sub-pixel motion: resampling the history across the edge in linear
// colour carries a large fraction of the light into the dark side (an HDR ghost many times the dark value); in the
// compressed space (hdrCompress) the same filter moves a bounded amount. The dark pixels beside the edge are
// compared with and without it.
TEST(TAAPass, HdrCompressionBoundsBleedingOfABrightEdgeUnderMotion) {
    const float light = 50.f, dark = 0.05f;
    auto edge = [&](uint64_t, uint32_t x, uint32_t) { return glm::vec4(glm::vec3(x < 32 ? light : dark), 1.f); };
    double excess[2] = {0, 0};
    for (int compress = 0; compress < 2; ++compress) {
        Harness h(nlohmann::json{{"hdrCompress", compress == 1}});
        h.source->color = edge;
        h.source->motion = [](uint64_t, uint32_t, uint32_t) {
            return glm::vec2(-0.37f / 64.f, -0.21f / 64.f);
        };  // history from the light's side
        h.run(8);
        for (uint32_t y = 8; y < 56; ++y)
            for (uint32_t x = 32; x < 36; ++x)
                excess[compress] = std::max(excess[compress], double(h.out(x, y).x / dark));
    }
    std::printf("brightest dark pixel beside the edge: %.1fx the dark value linear, %.1fx compressed\n", excess[0],
                excess[1]);
    EXPECT_GT(excess[0], 20.0) << "the uncompressed resolve is expected to bleed (else this test shows nothing)";
    EXPECT_LT(excess[1], 0.5 * excess[0]);  // measured 128x linear, 42x compressed (the motion vectors here are wrong
                                            // for the static content on purpose: every frame resamples across the edge)
}

TEST(TAAPass, ReflectionDoesNotDependOnParameters) {
    auto fieldsWith = [](const nlohmann::json& params) { return test::reflectedFields(registry(), "TAAPass", params); };
    const auto reference = fieldsWith(nlohmann::json::object());
    EXPECT_EQ(fieldsWith({{"alpha", 0.5f}, {"sigma", 3.f}, {"antiFlicker", false}, {"reference", true}}), reference);
}
