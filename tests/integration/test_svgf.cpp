// SVGFPass: properties, not snapshots. A constant signal passes through at any iteration count; on the Cornell
// box at 1 spp the error against a converged reference falls over frames and ends far below the input's;
// disoccluded pixels restart their history while visible ones keep it; non-finite input never reaches an output
// or the history; the feedback tap selects exactly which level becomes history; without `temporal` frames are
// independent; the direct/indirect split agrees with the combined signal; any thread count gives the same bits.
// The kernels on their own: passes/SVGF/tests/.
#include <gtest/gtest.h>
#include <hwy/targets.h>

#include <cmath>
#include <cstdio>
#include <functional>
#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <utility>
#include <vector>

#include "TestUtil.h"
#include "loom/Camera.h"
#include "loom/Graph.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

/// One pixel of the synthetic inputs.
struct GPixel {
    glm::vec4 color{0.f}, direct{0.f}, indirect{0.f}, albedo{1.f}, emission{0.f}, normW{0.f, 0.f, 1.f, 0.f};
    glm::vec2 linearZ{5.f, 0.01f}, mvec{0.f};
    uint32_t meshId = 0;
    glm::vec2 gradient{0.f};  ///< (luminance re-shaded now, then), emitted by the gradient source only
};
using GFn = std::function<GPixel(uint64_t frame, uint32_t x, uint32_t y)>;

/// Emits every SVGF input from a function of (frame, x, y); with `split`, also direct and indirect.
class SyntheticSource final : public RenderPass {
public:
    explicit SyntheticSource(bool split, bool gradient = false) : mSplit(split), mGradient(gradient) {}
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.output("color", Format::RGBA32F);
        if (mSplit) {
            r.output("direct", Format::RGBA32F);
            r.output("indirect", Format::RGBA32F);
        }
        r.output("albedo", Format::RGBA32F);
        r.output("emission", Format::RGBA32F);
        r.output("linearZ", Format::RG32F);
        r.output("normW", Format::RGBA32F);
        r.output("mvec", Format::RG32F);
        r.output("meshId", Format::R32U);
        if (mGradient) r.output("gradient", Format::RG32F);
    }
    void execute(PassContext& ctx) override {
        auto color = ctx.output("color")->view<glm::vec4>();
        for (uint32_t y = 0; y < color.height; ++y) {
            for (uint32_t x = 0; x < color.width; ++x) {
                const GPixel p = fn(ctx.frameIndex(), x, y);
                color.at(x, y) = p.color;
                if (mSplit) {
                    ctx.output("direct")->view<glm::vec4>().at(x, y) = p.direct;
                    ctx.output("indirect")->view<glm::vec4>().at(x, y) = p.indirect;
                }
                ctx.output("albedo")->view<glm::vec4>().at(x, y) = p.albedo;
                ctx.output("emission")->view<glm::vec4>().at(x, y) = p.emission;
                ctx.output("linearZ")->view<glm::vec2>().at(x, y) = p.linearZ;
                ctx.output("normW")->view<glm::vec4>().at(x, y) = p.normW;
                ctx.output("mvec")->view<glm::vec2>().at(x, y) = p.mvec;
                ctx.output("meshId")->view<uint32_t>().at(x, y) = p.meshId;
                if (mGradient) ctx.output("gradient")->view<glm::vec2>().at(x, y) = p.gradient;
            }
        }
    }
    GFn fn;

private:
    bool mSplit, mGradient;
};

PluginRegistry& registry() {
    static const bool registered = [] {
        auto& r = test::pluginRegistry();
        r.registerPass("SvgfSource", "synthetic SVGF inputs", [] { return std::make_unique<SyntheticSource>(false); });
        r.registerPass("SvgfSplitSource", "synthetic SVGF inputs with direct/indirect",
                       [] { return std::make_unique<SyntheticSource>(true); });
        r.registerPass("SvgfGradientSource", "synthetic SVGF inputs with temporal gradients",
                       [] { return std::make_unique<SyntheticSource>(false, true); });
        return true;
    }();
    (void)registered;
    return test::pluginRegistry();
}

/// SVGF's history fields in a compiled graph (which ones exist depends on its connections).
std::vector<std::string> historyFields(const RenderGraph& g) {
    std::vector<std::string> names;
    for (const auto& r : g.plan().resources)
        if (r.kind == ResourceKind::History && r.name.rfind("SVGF.", 0) == 0) names.push_back(r.name.substr(5));
    return names;
}

/// Source -> SVGF on synthetic inputs, run frame by frame.
struct Harness {
    Harness(const nlohmann::json& params, GFn fn, bool split = false, uint32_t w = 32, uint32_t h = 32,
            const char* source = nullptr)
        : graph(describe(params, source ? source : split ? "SvgfSplitSource" : "SvgfSource"), registry()) {
        CompileOptions o;
        o.width = w;
        o.height = h;
        o.observe = {"SVGF.estimate"};
        o.poisonTransients = true;  // a read of scratch before it is written shows up as NaN
        graph.compile(o);
        dynamic_cast<SyntheticSource*>(graph.pass("Source"))->fn = std::move(fn);
    }
    static GraphDesc describe(const nlohmann::json& params, const char* source) {
        nlohmann::json g = {{"loom_graph", 1},
                            {"name", "svgf"},
                            {"passes",
                             {{{"name", "Source"}, {"type", source}},
                              {{"name", "SVGF"},
                               {"type", "SVGFPass"},
                               {"params", params.is_null() ? nlohmann::json::object() : params}}}},
                            {"outputs", {"SVGF.filtered", "SVGF.variance", "SVGF.historyLength"}}};
        return parseGraph(g.dump());
    }
    void run(int frames = 1, const Camera* camera = nullptr) {
        for (int i = 0; i < frames; ++i) {
            FrameInfo f;
            f.frameIndex = next++;
            f.camera = camera;
            graph.execute(f);
        }
    }
    const Texture& field(const std::string& name) const {
        const Texture* t = graph.fieldTexture("SVGF." + name);
        if (!t) throw std::runtime_error("no texture for SVGF." + name);
        return *t;
    }
    glm::vec4 filtered(uint32_t x, uint32_t y) const { return field("filtered").view<glm::vec4>().at(x, y); }
    float length(uint32_t x, uint32_t y) const { return field("historyLength").view<float>().at(x, y); }
    double stat(const std::string& name) const {
        auto stats = graph.lastStats();
        auto it = stats.at("SVGF").find(name);
        return it == stats.at("SVGF").end() ? std::nan("") : it->second;
    }
    RenderGraph graph;
    uint64_t next = 0;
};

/// A hash in [0, 1): noise that depends on frame and pixel only (and a salt, for independent streams).
float hash01(uint64_t frame, uint32_t x, uint32_t y, uint32_t salt = 0) {
    return test::hash01(frame + (uint64_t(salt) << 40), x, y);
}

/// Noisy colour on two depth planes with a checker albedo: a non-trivial signal for the tests below.
GPixel noisyPixel(uint64_t frame, uint32_t x, uint32_t y) {
    GPixel p;
    p.albedo = ((x / 4 + y / 4) % 2) ? glm::vec4(0.8f, 0.6f, 0.4f, 1.f) : glm::vec4(0.3f, 0.5f, 0.7f, 1.f);
    const float n = hash01(frame, x, y);
    p.color = glm::vec4(glm::vec3(p.albedo) * (0.2f + 1.6f * n * n), 1.f);
    p.linearZ = x < 16 ? glm::vec2(4.f, 0.02f) : glm::vec2(6.f, 0.03f);
    p.meshId = x < 16 ? 0 : 1;
    return p;
}

bool allFinite(const Texture& t) {
    const uint32_t channels = formatInfo(t.format()).channels;
    for (uint32_t y = 0; y < t.height(); ++y)
        for (uint32_t x = 0; x < t.width(); ++x)
            for (uint32_t c = 0; c < channels; ++c)
                if (!std::isfinite(t.texel(x, y, c))) return false;
    return true;
}

double maxAbsDiff(const Texture& a, const Texture& b, uint32_t channels = 4) {
    double m = 0.0;
    for (uint32_t y = 0; y < a.height(); ++y)
        for (uint32_t x = 0; x < a.width(); ++x)
            for (uint32_t c = 0; c < channels; ++c)
                m = std::max(m, std::fabs(double(a.texel(x, y, c)) - double(b.texel(x, y, c))));
    return m;
}

Texture copyOf(const Texture& t) {
    Texture c(t.width(), t.height(), t.format());
    c.copyFrom(t);
    return c;
}

}  // namespace

// A constant image over a constant G-buffer is a fixed point of every stage: demodulation and remodulation
// invert each other, the moments have zero variance and every filter has normalised weights. Miss pixels pass
// through exactly.
TEST(SVGF, ConstantImagePassesThroughUnchanged) {
    const glm::vec3 albedo(0.5f, 0.6f, 0.7f), light(0.9f, 0.4f, 1.3f), emission(0.1f, 0.f, 0.05f);
    const glm::vec4 color(albedo * light + emission, 1.f), sky(3.f, 2.f, 1.f, 1.f);
    auto fn = [&](uint64_t, uint32_t x, uint32_t y) {
        GPixel p;
        p.albedo = glm::vec4(albedo, 1.f);
        p.emission = glm::vec4(emission, 1.f);
        p.color = color;
        if (x < 3 && y < 3) {  // a corner of sky
            p.color = sky;
            p.linearZ = glm::vec2(-1.f, 0.f);
            p.meshId = ~0u;
        }
        return p;
    };
    for (bool temporal : {true, false}) {
        for (int iterations = 0; iterations <= 5; ++iterations) {
            Harness h({{"iterations", iterations}, {"temporal", temporal}}, fn);
            for (int frame = 0; frame < 5; ++frame) {
                h.run();
                for (uint32_t y = 0; y < 32; ++y) {
                    for (uint32_t x = 0; x < 32; ++x) {
                        const glm::vec4 got = h.filtered(x, y), want = x < 3 && y < 3 ? sky : color;
                        for (int c = 0; c < 4; ++c)
                            ASSERT_NEAR(got[c], want[c], 2e-6f * std::fabs(want[c]))
                                << "temporal " << temporal << " iterations " << iterations << " frame " << frame
                                << " pixel " << x << "," << y << " channel " << c;
                    }
                }
                EXPECT_EQ(h.length(16, 16), temporal ? float(frame + 1) : 1.f);
                EXPECT_EQ(h.length(0, 0), 0.f) << "a miss pixel has no history";
            }
        }
    }
}

// Nothing is tied to one frame size: after a resize SVGF runs at the new size (history restarts) and a constant
// image still passes through.
TEST(SVGF, RunsAtWhateverSizeItsInputsHave) {
    const glm::vec4 color(0.3f, 0.2f, 0.1f, 1.f);
    auto fn = [&](uint64_t, uint32_t, uint32_t) {
        GPixel p;
        p.albedo = glm::vec4(0.5f, 0.5f, 0.5f, 1.f);
        p.color = color;
        return p;
    };
    Harness h({}, fn);
    h.run(2);
    for (auto [w, h2] : {std::pair<uint32_t, uint32_t>{50, 20}, {17, 61}}) {
        h.graph.resize(w, h2);
        h.run(2);
        const Texture& out = h.field("filtered");
        ASSERT_EQ(out.width(), w);
        ASSERT_EQ(out.height(), h2);
        for (uint32_t y = 0; y < h2; ++y)
            for (uint32_t x = 0; x < w; ++x)
                for (int c = 0; c < 4; ++c) ASSERT_NEAR(h.filtered(x, y)[c], color[c], 1e-6f) << x << "," << y;
        EXPECT_EQ(h.length(w / 2, h2 / 2), 2.f);
    }
}

// A square moving right by 4 pixels a frame over a static background. The strip it uncovers fails the mesh and
// depth tests: its pixels restart their history (length 1) unless the 3x3 fallback finds background that was
// visible last frame right next to them (the strip's rim), whose history they take, never the square's. The
// square, followed through its motion vector, and the background that stays visible keep accumulating.
TEST(SVGF, DisoccludedPixelsRestartHistory) {
    const uint32_t W = 64, H = 32, speed = 4;
    auto inSquare = [&](uint64_t frame, int x, int y) {
        return y >= 8 && y < 16 && x >= int(4 + speed * frame) && x < int(12 + speed * frame);
    };
    auto fn = [&](uint64_t frame, uint32_t x, uint32_t y) {
        GPixel p = noisyPixel(frame, x, y);
        p.meshId = 0;
        p.linearZ = glm::vec2(5.f, 0.01f);
        if (inSquare(frame, int(x), int(y))) {
            p.linearZ = glm::vec2(2.f, 0.004f);
            p.normW = glm::vec4(0.f, 0.6f, 0.8f, 0.f);
            p.meshId = 7;
            p.mvec = glm::vec2(-float(speed) / float(W), 0.f);  // exact in float: W is a power of two
        }
        return p;
    };
    Harness h({}, fn, false, W, H);
    h.run();
    Texture prev = copyOf(h.field("historyLength"));
    for (uint64_t frame = 1; frame < 8; ++frame) {
        h.run();
        int restarted = 0, tracked = 0, kept = 0;
        for (int y = 0; y < int(H); ++y) {
            for (int x = 0; x < int(W); ++x) {
                const bool now = inSquare(frame, x, y), before = inSquare(frame - 1, x, y);
                const float len = h.length(uint32_t(x), uint32_t(y));
                const std::string where =
                    "frame " + std::to_string(frame) + " pixel " + std::to_string(x) + "," + std::to_string(y);
                if (now) {
                    // The square, tracked through its motion vector since frame 0 (its leading edge included).
                    EXPECT_EQ(len, float(frame + 1)) << where;
                    ++tracked;
                } else if (before) {
                    // The 3x3 fallback: the mean history of the neighbours that were background last frame.
                    float sum = 0.f, count = 0.f;
                    for (int j = -1; j <= 1; ++j)
                        for (int i = -1; i <= 1; ++i)
                            if (x + i >= 0 && y + j >= 0 && !inSquare(frame - 1, x + i, y + j)) {
                                sum += prev.texel(uint32_t(x + i), uint32_t(y + j), 0);
                                count += 1.f;
                            }
                    if (count == 0.f) {
                        EXPECT_EQ(len, 1.f) << where << " uncovered";
                        ++restarted;
                    } else {
                        EXPECT_NEAR(len, sum / count + 1.f, 1e-5f) << where << " uncovered, next to background";
                    }
                } else {
                    EXPECT_EQ(len, std::min(prev.texel(uint32_t(x), uint32_t(y), 0) + 1.f, 32.f)) << where;
                    ++kept;
                }
            }
        }
        EXPECT_EQ(restarted, 18) << "frame " << frame;  // 3 columns x 6 rows of the 4 x 8 strip
        EXPECT_EQ(tracked, 64);
        EXPECT_GT(kept, 0);
        prev = copyOf(h.field("historyLength"));
    }
}

// NaN and Inf in one frame's colour never reach the outputs or the history, and are counted.
TEST(SVGF, NonFiniteInputNeverReachesOutputsOrHistory) {
    for (bool split : {false, true}) {
        auto fn = [&](uint64_t frame, uint32_t x, uint32_t y) {
            GPixel p = noisyPixel(frame, x, y);
            p.direct = p.color * 0.7f;
            p.indirect = p.color - p.direct;
            if (frame == 3 && x == 10 && y == 10) p.color = p.direct = glm::vec4(NAN, 1.f, 1.f, 1.f);
            if (frame == 3 && x == 20 && y == 5) p.color = p.indirect = glm::vec4(INFINITY, 0.f, -INFINITY, 1.f);
            if (frame == 3 && x == 21 && y == 5) p.color = p.direct = glm::vec4(3e38f, 3e38f, 3e38f, 1.f);
            return p;
        };
        Harness h({}, fn, split);
        h.run(3);
        for (int frame = 3; frame < 5; ++frame) {
            h.run();
            for (const char* out : {"filtered", "variance", "historyLength"})
                EXPECT_TRUE(allFinite(h.field(out))) << out << " frame " << frame << " split " << split;
            for (const auto& hist : historyFields(h.graph))
                EXPECT_TRUE(allFinite(h.field(hist))) << hist << " frame " << frame << " split " << split;
            if (frame == 3) {
                EXPECT_EQ(h.stat("nonFinite"), 2.0);
            }
        }
    }
}

// Level feedbackTap of the à-trous chain is next frame's colour history: -1 the unfiltered estimate, the last level
// the filtered result itself, an inner level what a shorter chain would output.
TEST(SVGF, FeedbackTapSelectsTheHistoryLevel) {
    auto fn = [](uint64_t frame, uint32_t x, uint32_t y) {
        GPixel p = noisyPixel(frame, x, y);
        p.albedo = glm::vec4(1.f);
        p.color = glm::vec4(glm::vec3(0.2f + hash01(frame, x, y, 1)), 1.f);
        return p;
    };
    auto historyAfterOneFrame = [&](int iterations, int tap, Texture* filtered = nullptr, Texture* estimate = nullptr) {
        Harness h({{"iterations", iterations}, {"feedbackTap", tap}}, fn);
        h.run();
        if (filtered) *filtered = copyOf(h.field("filtered"));
        if (estimate) *estimate = copyOf(h.field("estimate"));
        return copyOf(h.field("illumination"));
    };
    Texture filtered2, estimate, filtered1;
    const Texture tapNone = historyAfterOneFrame(2, -1, nullptr, &estimate);
    const Texture tap0 = historyAfterOneFrame(2, 0);
    const Texture tap1 = historyAfterOneFrame(2, 1, &filtered2);
    const Texture tapClamped = historyAfterOneFrame(2, 5);
    historyAfterOneFrame(1, 1, &filtered1);
    EXPECT_TRUE(tapNone.samePixels(estimate)) << "tap -1: the unfiltered signal with its variance estimate";
    EXPECT_EQ(maxAbsDiff(tap1, filtered2, 3), 0.0) << "the last level is the filtered result (albedo 1)";
    EXPECT_EQ(maxAbsDiff(tap0, filtered1, 3), 0.0) << "level 0 is what one iteration outputs";
    EXPECT_TRUE(tapClamped.samePixels(tap1)) << "a tap past the last level is clamped to it";
    EXPECT_GT(maxAbsDiff(tap0, tap1, 3), 1e-3) << "the levels differ, so the comparisons above mean something";
    EXPECT_GT(maxAbsDiff(tapNone, tap0, 3), 1e-3);

    // The chosen level is what the next frame reprojects, so different taps give different second frames.
    Harness a({{"iterations", 2}, {"feedbackTap", 0}}, fn), b({{"iterations", 2}, {"feedbackTap", 1}}, fn);
    a.run(2);
    b.run(2);
    EXPECT_GT(maxAbsDiff(a.field("filtered"), b.field("filtered"), 3), 1e-4);
}

// Without `temporal` every frame is filtered on its own: the same input gives the same output whatever came
// before. With it, the history changes the result.
TEST(SVGF, TemporalOffMakesFramesIndependent) {
    auto seeded = [](uint64_t seed) {
        return [seed](uint64_t frame, uint32_t x, uint32_t y) { return noisyPixel(seed == 0 ? frame : seed, x, y); };
    };
    for (bool temporal : {false, true}) {
        // Frames 0..3 see different noise; frame 4 sees the noise of "frame 100" in both harnesses.
        auto late = [](uint64_t frame, uint32_t x, uint32_t y) { return noisyPixel(frame < 4 ? frame : 100, x, y); };
        Harness withPast({{"temporal", temporal}}, late);
        withPast.run(5);
        Harness fresh({{"temporal", temporal}}, seeded(100));
        fresh.run();
        if (!temporal) {
            EXPECT_TRUE(withPast.field("filtered").samePixels(fresh.field("filtered")));
            EXPECT_EQ(withPast.length(5, 5), 1.f);
        } else {
            EXPECT_GT(maxAbsDiff(withPast.field("filtered"), fresh.field("filtered"), 3), 1e-3);
        }
    }
}

// A constant light field (demodulated direct and indirect constant, emission in direct as the path tracer puts
// it) over a checker albedo: split and combined filtering both return the input, so they agree.
TEST(SVGF, DirectIndirectSplitAgreesWithCombined) {
    const glm::vec3 direct(0.6f, 0.5f, 0.4f), indirect(0.2f, 0.3f, 0.1f), emission(2.f, 1.5f, 1.f);
    auto fn = [&](uint64_t, uint32_t x, uint32_t y) {
        GPixel p;
        p.albedo = ((x / 3 + y / 5) % 2) ? glm::vec4(0.8f, 0.6f, 0.4f, 1.f) : glm::vec4(0.1f, 0.5f, 0.9f, 1.f);
        const glm::vec3 e = (x >= 20 && y >= 20) ? emission : glm::vec3(0.f);
        p.emission = glm::vec4(e, 1.f);
        p.direct = glm::vec4(glm::vec3(p.albedo) * direct + e, 1.f);
        p.indirect = glm::vec4(glm::vec3(p.albedo) * indirect, 1.f);
        p.color = glm::vec4(glm::vec3(p.direct) + glm::vec3(p.indirect), 1.f);
        p.linearZ = x < 16 ? glm::vec2(4.f, 0.02f) : glm::vec2(6.f, 0.03f);
        return p;
    };
    Harness combined({}, fn, false), split({}, fn, true);
    for (int frame = 0; frame < 4; ++frame) {
        combined.run();
        split.run();
        EXPECT_EQ(combined.stat("split"), 0.0);
        EXPECT_EQ(split.stat("split"), 1.0);
        for (uint32_t y = 0; y < 32; ++y) {
            for (uint32_t x = 0; x < 32; ++x) {
                const glm::vec4 want = fn(0, x, y).color, a = combined.filtered(x, y), b = split.filtered(x, y);
                for (int c = 0; c < 3; ++c) {
                    ASSERT_NEAR(a[c], want[c], 4e-6f * want[c]) << x << "," << y << " combined";
                    ASSERT_NEAR(b[c], want[c], 4e-6f * want[c]) << x << "," << y << " split";
                }
            }
        }
    }
}

namespace {

/// GBufferRT + PathTracer (1 spp) + SVGF on a data scene. With prevEdges, SVGF reads last frame's guides from the
/// G-buffer's @prev outputs (as the shipped graphs do); without, it keeps its own copies.
std::unique_ptr<RenderGraph> sceneGraph(const std::shared_ptr<Scene>& scene, uint32_t w, uint32_t h,
                                        const nlohmann::json& svgfParams, bool prevEdges = false,
                                        const CompileOptions& base = {}) {
    auto edge = [](const std::string& a, const std::string& b) { return nlohmann::json::array({a, b}); };
    // GBufferRT and the path tracer both offer albedo, specAlbedo and emission: take the G-buffer's.
    nlohmann::json edges =
        nlohmann::json::array({edge("GBuffer.albedo", "SVGF.albedo"), edge("GBuffer.specAlbedo", "SVGF.specAlbedo"),
                               edge("GBuffer.emission", "SVGF.emission"), edge("GBuffer.vbuffer", "PT.vbuffer")});
    if (prevEdges)
        for (const std::string c : {"linearZ", "normW", "meshId"})
            edges.push_back(edge("GBuffer." + c + "@prev", "SVGF." + c + "Prev"));
    nlohmann::json g = {{"loom_graph", 1},
                        {"name", "svgf_scene"},
                        {"passes",
                         {{{"name", "GBuffer"}, {"type", "GBufferRT"}},
                          {{"name", "PT"}, {"type", "PathTracer"}},
                          {{"name", "SVGF"}, {"type", "SVGFPass"}, {"params", svgfParams}}}},
                        {"edges", edges},
                        {"outputs", {"SVGF.filtered", "SVGF.historyLength", "PT.color"}}};
    return test::compiledGraph(g, scene, w, h, base);
}

void renderFrame(RenderGraph& g, Scene& scene, uint64_t frame, double time, uint32_t w, uint32_t h) {
    scene.update(time);
    scene.camera.aspect = float(w) / float(h);
    scene.camera.beginFrame(frame);
    g.execute(FrameInfo{frame, time, &scene, &scene.camera});
}

/// relMSE of the RGB of `img` against `ref` (Rousselle et al.: (x - r)^2 / (r^2 + 0.01), averaged).
double relMSE(const Texture& img, const std::vector<glm::dvec3>& ref) {
    double sum = 0.0;
    const auto v = img.view<glm::vec4>();
    for (uint32_t y = 0; y < img.height(); ++y)
        for (uint32_t x = 0; x < img.width(); ++x) {
            const glm::dvec3 r = ref[size_t(y) * img.width() + x], d = glm::dvec3(glm::vec3(v.at(x, y))) - r;
            for (int c = 0; c < 3; ++c) sum += d[c] * d[c] / (r[c] * r[c] + 0.01);
        }
    return sum / (3.0 * img.width() * img.height());
}

}  // namespace

// Static camera on the Cornell box at 1 spp: SVGF's error against a many-sample reference ends far below the error
// of the 1 spp input. Without filtered feedback (the default feedbackTap -1) it keeps falling as history builds up;
// with feedbackTap 0 it falls until the temporal variance takes over (frame 4) and then settles at a higher level,
// since each frame re-filters the already filtered history (the over-blurring bias of feedback).
TEST(SVGF, ConvergesTowardsReferenceOnCornellBox) {
    const uint32_t W = 96, H = 96;
    auto scene = Scene::load(test::dataScene("cornell_box.gltf"));
    // Reference: the mean of many path-traced frames (the same path tracer, so the same expectation).
    std::vector<glm::dvec3> ref(size_t(W) * H, glm::dvec3(0.0));
    {
        nlohmann::json g = {
            {"loom_graph", 1},
            {"name", "ref"},
            {"passes", {{{"name", "PT"}, {"type", "PathTracer"}, {"params", {{"samplesPerPixel", 64}}}}}},
            {"outputs", {"PT.color"}}};
        RenderGraph graph(parseGraph(g.dump()), registry());
        graph.setScene(scene);
        CompileOptions o;
        o.width = W;
        o.height = H;
        graph.compile(o);
        const int frames = 8;
        for (int f = 0; f < frames; ++f) {
            renderFrame(graph, *scene, 1000 + f, 0.0, W, H);
            const auto c = graph.fieldTexture("PT.color")->view<glm::vec4>();
            for (uint32_t y = 0; y < H; ++y)
                for (uint32_t x = 0; x < W; ++x)
                    ref[size_t(y) * W + x] += glm::dvec3(glm::vec3(c.at(x, y))) / double(frames);
        }
    }
    // Without the firefly clamp, which is biased (it drops the energy above its bound): SVGF then converges to the
    // path tracer's expectation. With it (the default), the error stays within a bound.
    auto defaults = sceneGraph(scene, W, H, {{"feedbackTap", 0}, {"outlierSigma", 0}});
    auto noFeedback = sceneGraph(scene, W, H, {{"outlierSigma", 0}});
    auto clamped = sceneGraph(scene, W, H, nlohmann::json::object());
    const int frames = 24;
    std::vector<double> errDefault, errNoFeedback, errClamped;
    double inputError = 0.0;
    for (int f = 0; f < frames; ++f) {
        renderFrame(*defaults, *scene, uint64_t(f), 0.0, W, H);
        errDefault.push_back(relMSE(*defaults->fieldTexture("SVGF.filtered"), ref));
        inputError += relMSE(*defaults->fieldTexture("PT.color"), ref) / frames;
        renderFrame(*noFeedback, *scene, uint64_t(f), 0.0, W, H);
        errNoFeedback.push_back(relMSE(*noFeedback->fieldTexture("SVGF.filtered"), ref));
        renderFrame(*clamped, *scene, uint64_t(f), 0.0, W, H);
        errClamped.push_back(relMSE(*clamped->fieldTexture("SVGF.filtered"), ref));
    }
    std::printf("relMSE with the default firefly clamp, frame 1 / 4 / 8 / 24: %.4f %.4f %.4f %.4f\n", errClamped[0],
                errClamped[3], errClamped[7], errClamped[23]);
    std::printf(
        "relMSE: 1 spp input %.4f; SVGF frame 1 / 4 / 8 / 24: feedbackTap 0 %.4f %.4f %.4f %.4f, -1 (default) "
        "%.4f %.4f %.4f %.4f\n",
        inputError, errDefault[0], errDefault[3], errDefault[7], errDefault[23], errNoFeedback[0], errNoFeedback[3],
        errNoFeedback[7], errNoFeedback[23]);
    EXPECT_LT(errNoFeedback[3], errNoFeedback[0]);
    EXPECT_LT(errNoFeedback[7], errNoFeedback[3]);
    EXPECT_LT(errNoFeedback[23], errNoFeedback[7]);
    EXPECT_LT(errNoFeedback[23], 0.05 * inputError);
    EXPECT_LT(errDefault[4], errDefault[0]);
    for (int f = 0; f < frames; ++f) EXPECT_LT(errDefault[f], 0.15 * inputError) << "frame " << f;
}

// The same frames with 1 and 2 threads give the same bits, on the animated scene (reprojection, disocclusion).
TEST(SVGF, BitIdenticalForAnyThreadCount) {
    const uint32_t W = 64, H = 64;
    auto render = [&](unsigned threads) {
        ThreadLimit limit(threads);
        auto scene = Scene::load(test::dataScene("cornell_dynamic.gltf"));
        auto graph = sceneGraph(scene, W, H, nlohmann::json::object());
        for (int f = 0; f < 4; ++f) renderFrame(*graph, *scene, uint64_t(f), 0.5 + f / 30.0, W, H);
        std::vector<Texture> out;
        out.push_back(copyOf(*graph->fieldTexture("SVGF.filtered")));
        for (const auto& hist : historyFields(*graph)) out.push_back(copyOf(*graph->fieldTexture("SVGF." + hist)));
        return out;
    };
    const auto one = render(1), two = render(2);
    for (size_t i = 0; i < one.size(); ++i) EXPECT_TRUE(one[i].samePixels(two[i])) << "field " << i;
}

// The fused, vectorised temporal stage (default) performs the reference stages' float operations in their order:
// every history field is bit-identical to running temporalPixel, varianceEstimatePixel and modulatePixel one after
// the other (referenceStages), and the output (remodulated inside the last à-trous level) agrees within rounding,
// on the animated scene (camera and objects move: footprints with differing offsets, disocclusion, the 3x3
// fallback) and on synthetic input with a sub-pixel pan, emission, non-finite samples and misses, for the
// combined signal and for the direct/indirect split.
TEST(SVGF, FusedStagesMatchTheReferenceStages) {
    auto expectSameOutput = [](const Texture& a, const Texture& b, const std::string& where) {
        for (uint32_t y = 0; y < a.height(); ++y)
            for (uint32_t x = 0; x < a.width(); ++x)
                for (uint32_t c = 0; c < 4; ++c) {
                    const float u = a.texel(x, y, c), v = b.texel(x, y, c);
                    ASSERT_NEAR(u, v, 3e-7f * std::fabs(v)) << where << " pixel " << x << "," << y << " channel " << c;
                }
    };
    const uint32_t W = 64, H = 64;
    const int frames = 6;
    auto scene = [&](bool reference) {
        auto s = Scene::load(test::dataScene("cornell_dynamic.gltf"));
        auto graph = sceneGraph(s, W, H, {{"referenceStages", reference}});
        std::vector<Texture> out;
        for (int f = 0; f < frames; ++f) {
            renderFrame(*graph, *s, uint64_t(f), 0.5 + f / 30.0, W, H);
            out.push_back(copyOf(*graph->fieldTexture("SVGF.filtered")));
            for (const auto& hist : historyFields(*graph)) out.push_back(copyOf(*graph->fieldTexture("SVGF." + hist)));
        }
        return out;
    };
    const auto fused = scene(false), reference = scene(true);
    const size_t perFrame = fused.size() / frames;  // the output, then the history fields
    for (size_t i = 0; i < fused.size(); ++i) {
        if (i % perFrame == 0)
            expectSameOutput(fused[i], reference[i], "scene, frame " + std::to_string(i / perFrame));
        else
            EXPECT_TRUE(fused[i].samePixels(reference[i])) << "scene, field " << i;
    }

    // A pan of 0.37 px a frame (bilinear weights of every kind), sky, and bad samples in frame 3. Emission on
    // every fourth row only, and one pixel with alpha 0.5 and one with a NaN alpha among hits, so the remodulation
    // reads colour and emission on some rows and skips them on others (Remodulation::groups).
    auto fn = [](uint64_t frame, uint32_t x, uint32_t y) {
        GPixel p = noisyPixel(frame, x, y);
        p.mvec = glm::vec2(-0.37f / 48.f, 0.21f / 40.f);
        p.emission = glm::vec4(x % 7 == 0 && y % 4 == 1 ? 0.3f : 0.f, 0.f, 0.f, 0.f);
        if (y < 3 || (x >= 41 && y >= 33)) {  // a band of sky and a corner of it that splits groups of pixels
            p.linearZ = glm::vec2(-1.f, 0.f);
            p.meshId = ~0u;
        }
        if (x == 20 && y == 14) p.color.a = 0.5f;
        if (x == 37 && y == 22) p.color.a = NAN;
        if (frame == 3 && x == 30 && y == 20) p.color = glm::vec4(NAN, 1.f, 1.f, 1.f);
        return p;
    };
    // Six frames of the fused stages (fast) against the reference stages on the same input.
    auto compareRuns = [&](const GFn& input, bool split, const Camera* camera = nullptr,
                           const nlohmann::json& params = nlohmann::json::object()) {
        const std::string what =
            std::string(split ? "split " : "") + (camera ? "moving camera " : "") + (params.empty() ? "" : params.dump());
        nlohmann::json fastParams = params, refParams = params;
        fastParams["referenceStages"] = false;
        refParams["referenceStages"] = true;
        Harness fast(fastParams, input, split, 48, 40);
        Harness ref(refParams, input, split, 48, 40);
        for (int frame = 0; frame < 6; ++frame) {
            fast.run(1, camera);
            ref.run(1, camera);
            EXPECT_EQ(fast.stat("split"), split ? 1.0 : 0.0);
            EXPECT_EQ(fast.stat("nonFinite"), ref.stat("nonFinite"));
            EXPECT_EQ(ref.stat("temporal.referenceShare"), 1.0);
            // The vector path did most of the work (the frame border, the pan's edge and the bad sample did not);
            // under the moving camera most taps fail the depth test and the reference's 3x3 search takes them.
            if (!camera) EXPECT_LT(fast.stat("temporal.referenceShare"), 0.5) << what << "frame " << frame;
            // Likewise the spatial variance of the first frames (short history everywhere; later, the pan's edge).
            if (frame == 0) {
                EXPECT_EQ(fast.stat("variance.spatialPixels"), 48.0 * 37.0 - 7.0 * 7.0) << what;  // sky: 3 rows, 7x7
            }
            if (frame < 3) {
                EXPECT_LT(fast.stat("variance.referenceShare"), 0.5) << what << "frame " << frame;
            }
            expectSameOutput(fast.field("filtered"), ref.field("filtered"), what + "frame " + std::to_string(frame));
            for (const char* name : {"variance", "historyLength", "estimate", "prevMeshId"})
                EXPECT_TRUE(fast.field(name).samePixels(ref.field(name))) << what << name << " frame " << frame;
            ASSERT_EQ(historyFields(fast.graph), historyFields(ref.graph));
            for (const auto& hist : historyFields(fast.graph))
                EXPECT_TRUE(fast.field(hist).samePixels(ref.field(hist))) << what << hist << " frame " << frame;
        }
    };
    compareRuns(fn, false);
    // A camera that moved forward and turned since last frame: the disocclusion test's expected depth
    // (expectedPrevDepth) then varies over the frame, and some taps pass it while others fail.
    Camera moving;
    moving.aspect = 48.f / 40.f;
    moving.prevWorld = glm::mat4(1.f);
    moving.world = glm::translate(glm::mat4(1.f), glm::vec3(0.f, 0.f, -0.5f)) *
                   glm::rotate(glm::mat4(1.f), 0.03f, glm::vec3(0.2f, 1.f, 0.f));
    compareRuns(fn, false, &moving);

    // The direct/indirect split takes the same vector path for both signals, its remodulation fused into the
    // second signal's last level: the same pan, emission inside direct, an independent indirect noise, and a bad
    // indirect sample in frame 2.
    auto splitFn = [&](uint64_t frame, uint32_t x, uint32_t y) {
        GPixel p = fn(frame, x, y);
        const float n = test::hash01(frame + 1000, x, y);
        p.indirect = glm::vec4(glm::vec3(p.albedo) * (0.05f + 0.9f * n * n * n), 1.f);
        p.direct = glm::vec4(glm::vec3(p.color) * 0.7f + glm::vec3(p.emission), 1.f);
        if (frame == 2 && x == 11 && y == 33) p.indirect = glm::vec4(1.f, INFINITY, 1.f, 1.f);
        p.color = p.direct + glm::vec4(glm::vec3(p.indirect), 0.f);
        return p;
    };
    compareRuns(splitFn, true);
    // The firefly clamp, on both signals: the noise's bright tail lies beyond 1.5 standard deviations of the history
    // once it is 4 frames long (frames 4 and 5 here), so samples are clamped on both paths alike.
    compareRuns(fn, false, nullptr, {{"outlierSigma", 1.5}});
    compareRuns(splitFn, true, nullptr, {{"outlierSigma", 1.5}});
}

// With the G-buffer's @prev outputs connected, SVGF reads last frame's depth, normal and mesh id there instead of
// copying them into its own history: the same disocclusion decisions, so every output and history field is the same
// bit for bit as with its own copies, on a scene whose moving objects uncover and cover pixels; its copies are then
// not even allocated.
TEST(SVGF, PrevGuidesFromTheGBufferMatchItsOwnCopies) {
    const uint32_t W = 64, H = 64;
    auto sceneA = Scene::load(test::dataScene("cornell_dynamic.gltf"));
    auto sceneB = Scene::load(test::dataScene("cornell_dynamic.gltf"));
    auto copies = sceneGraph(sceneA, W, H, nlohmann::json::object(), false);
    auto shared = sceneGraph(sceneB, W, H, nlohmann::json::object(), true);
    bool sawRestart = false, sawLongHistory = false;
    for (int f = 0; f < 8; ++f) {
        const double time = 0.5 + f / 10.0;  // fast motion: disocclusions every frame
        renderFrame(*copies, *sceneA, uint64_t(f), time, W, H);
        renderFrame(*shared, *sceneB, uint64_t(f), time, W, H);
        EXPECT_EQ(copies->lastStats().at("SVGF").at("sharedPrevGuides"), 0.0);
        EXPECT_EQ(shared->lastStats().at("SVGF").at("sharedPrevGuides"), 1.0);
        for (const char* field : {"filtered", "historyLength", "illumination", "moments", "length"})
            EXPECT_TRUE(copies->fieldTexture(std::string("SVGF.") + field)
                            ->samePixels(*shared->fieldTexture(std::string("SVGF.") + field)))
                << field << " frame " << f;
        const Texture& length = *shared->fieldTexture("SVGF.historyLength");
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x) {
                const float n = length.texel(x, y, 0);
                sawRestart |= f > 0 && n == 1.f;
                sawLongHistory |= n >= float(f + 1) && f >= 4;
            }
        // The pass's own copies: written in one graph, not even allocated in the other.
        const Texture& ownCopy = *copies->fieldTexture("SVGF.prevLinearZ");
        EXPECT_FALSE(ownCopy.samePixels(Texture(W, H, ownCopy.format()))) << "frame " << f;
        for (const char* copy : {"SVGF.prevLinearZ", "SVGF.prevNormW", "SVGF.prevMeshId"})
            EXPECT_EQ(shared->fieldTexture(copy), nullptr) << copy;
    }
    EXPECT_TRUE(sawRestart) << "no disocclusion: the test would not tell last frame's guides from this frame's";
    EXPECT_TRUE(sawLongHistory);
}

// The fused path writes its estimate and integrated images only where the variance stage reads them (groups with a
// short history, and the integrated image near the left and right edges), unless the image is observed: then every
// pixel. Either way the results are the same, bit for bit; with poisoned
// transients the unobserved image keeps NaN where it was skipped and the observed one has none.
TEST(SVGF, ScratchImagesAreWrittenInFullOnlyWhenObserved) {
    const uint32_t W = 64, H = 64;
    auto sceneA = Scene::load(test::dataScene("cornell_dynamic.gltf"));
    auto sceneB = Scene::load(test::dataScene("cornell_dynamic.gltf"));
    CompileOptions poisoned;
    poisoned.poisonTransients = true;
    CompileOptions observed = poisoned;
    observed.observe = {"SVGF.estimate*", "SVGF.integrated*"};
    // Filtered feedback (feedbackTap 0): with the unfiltered signal as history (-1) the estimate is read in full.
    const nlohmann::json params = {{"feedbackTap", 0}};
    auto skipping = sceneGraph(sceneA, W, H, params, true, poisoned);
    auto full = sceneGraph(sceneB, W, H, params, true, observed);
    // The graph filters direct and indirect separately: the indirect signal's integrated image keeps what the
    // temporal stage wrote (the direct one's receives its filtered result later in the frame).
    Texture estimate, integrated;
    full->setFieldObserver([&](const FrameInfo&, const std::string&, const std::string& field, const Texture& t) {
        if (field == "estimate") estimate = copyOf(t);
        if (field == "integratedIndirect") integrated = copyOf(t);
    });
    bool skipped = false, skippedIntegrated = false;
    for (int f = 0; f < 8; ++f) {
        const double time = 0.5 + f / 30.0;
        renderFrame(*skipping, *sceneA, uint64_t(f), time, W, H);
        renderFrame(*full, *sceneB, uint64_t(f), time, W, H);
        for (const char* field : {"filtered", "illumination", "moments", "length"})
            EXPECT_TRUE(skipping->fieldTexture(std::string("SVGF.") + field)
                            ->samePixels(*full->fieldTexture(std::string("SVGF.") + field)))
                << field << " frame " << f;
        ASSERT_EQ(estimate.width(), W);
        ASSERT_EQ(integrated.width(), W);
        EXPECT_TRUE(allFinite(estimate)) << "an observed estimate is written everywhere, frame " << f;
        EXPECT_TRUE(allFinite(integrated)) << "likewise the integrated image, frame " << f;
        skipped |= !allFinite(*skipping->fieldTexture("SVGF.estimate"));
        skippedIntegrated |= !allFinite(*skipping->fieldTexture("SVGF.integratedIndirect"));
    }
    EXPECT_TRUE(skipped) << "with long histories the unobserved estimate is not written everywhere";
    EXPECT_TRUE(skippedIntegrated) << "nor the unobserved integrated image";
}

// Every stage's vector path does the reference's arithmetic (the temporal and variance stages in its order, the
// a-trous weights with the same roundings), so the pass gives the same bits whichever instruction set runs it:
// restricted to AVX2 against AVX-512, on the animated scene (direct and indirect, disocclusions every frame) and on
// synthetic input of the combined signal whose motion varies from pixel to pixel (gathered footprints) with a
// moving square that uncovers pixels (the 3x3 fallback).
TEST(SVGF, AVX512AndAVX2GiveTheSameBits) {
    if (!(hwy::SupportedTargets() & HWY_AVX3)) GTEST_SKIP() << "this CPU has no AVX-512";
    auto sameFields = [](const RenderGraph& a, const RenderGraph& b, const std::string& what) {
        std::vector<std::string> fields = historyFields(a);
        fields.push_back("filtered");
        for (const auto& field : fields)
            EXPECT_TRUE(a.fieldTexture("SVGF." + field)->samePixels(*b.fieldTexture("SVGF." + field)))
                << field << ", " << what;
    };
    const uint32_t W = 70, H = 40;  // 70: the last vector of a row is partial for 8 and 16 lanes
    auto sceneA = Scene::load(test::dataScene("cornell_dynamic.gltf"));
    auto sceneB = Scene::load(test::dataScene("cornell_dynamic.gltf"));
    auto wide = sceneGraph(sceneA, W, H, nlohmann::json::object());
    auto narrow = sceneGraph(sceneB, W, H, nlohmann::json::object());
    auto fn = [](uint64_t frame, uint32_t x, uint32_t y) {
        GPixel p = noisyPixel(frame, x, y);
        // A swirl: the motion, and the footprint's integer offset, change along every row.
        p.mvec = glm::vec2(0.02f * std::sin(0.3f * float(y)), 0.015f * std::cos(0.25f * float(x)));
        const uint32_t left = 10 + 3 * uint32_t(frame);
        if (x >= left && x < left + 12 && y >= 10 && y < 22) {
            p.linearZ = glm::vec2(2.f, 0.01f);
            p.meshId = 7;
        }
        return p;
    };
    Harness wideSynthetic({}, fn, false, W, H), narrowSynthetic({}, fn, false, W, H);
    for (int f = 0; f < 6; ++f) {
        hwy::SetSupportedTargetsForTest(0);
        renderFrame(*wide, *sceneA, uint64_t(f), 0.5 + f / 10.0, W, H);
        wideSynthetic.run();
        hwy::SetSupportedTargetsForTest(HWY_AVX2);
        renderFrame(*narrow, *sceneB, uint64_t(f), 0.5 + f / 10.0, W, H);
        narrowSynthetic.run();
        hwy::SetSupportedTargetsForTest(0);
        EXPECT_EQ(wide->lastStats().at("SVGF").at("split"), 1.0);
        EXPECT_EQ(wideSynthetic.stat("split"), 0.0);
        sameFields(*wide, *narrow, "scene, frame " + std::to_string(f));
        sameFields(wideSynthetic.graph, narrowSynthetic.graph, "synthetic, frame " + std::to_string(f));
    }
}

// SVGF declares the indirect signal's history and scratch only with the direct/indirect split, and its own copies
// of last frame's guides only without the @prev edges: a graph allocates what its connections use.
TEST(SVGF, FieldsFollowTheConnections) {
    const char* const indirect[] = {"illuminationIndirect", "momentsIndirect", "integratedIndirect",
                                    "estimateIndirect"};
    const char* const copies[] = {"prevLinearZ", "prevNormW", "prevMeshId"};
    auto has = [](const RenderGraph& g, const std::string& field) {
        for (const auto& r : g.plan().resources)
            if (r.name == "SVGF." + field) return true;
        return false;
    };
    const GFn flat = [](uint64_t, uint32_t, uint32_t) { return GPixel{}; };
    Harness combined({}, flat, false), split({}, flat, true);
    for (const char* f : indirect) {
        EXPECT_FALSE(has(combined.graph, f)) << f;
        EXPECT_TRUE(has(split.graph, f)) << f;
    }
    EXPECT_LT(combined.graph.plan().historyBytes, split.graph.plan().historyBytes);
    for (const char* f : copies) EXPECT_TRUE(has(combined.graph, f)) << f;  // no @prev edges in the harness
    // A scene graph with the @prev edges (the path tracer's direct and indirect wired by name: the split).
    auto scene = Scene::load(test::dataScene("cornell_dynamic.gltf"));
    auto withPrev = sceneGraph(scene, 32, 32, nlohmann::json::object(), true);
    for (const char* f : copies) EXPECT_FALSE(has(*withPrev, f)) << f;
    for (const char* f : indirect) EXPECT_TRUE(has(*withPrev, f)) << f;
    combined.run(2);
    split.run(2);
    EXPECT_EQ(combined.stat("split"), 0.0);
    EXPECT_EQ(split.stat("split"), 1.0);
}

// The edge-stopping parameters at the ends of their ranges (0: every luminance, normal or depth difference
// stops the filter, or none does) keep every output and history finite, through the spatial variance of the
// first frames and the temporal one after, on the vector stages and the reference ones.
TEST(SVGF, ExtremeEdgeStoppingParametersStayFinite) {
    // 0 and the largest value each accepts (phiNormal's bound keeps a pixel's own weight from vanishing).
    const std::pair<const char*, double> extremes[] = {{"phiColor", 0.0},  {"phiNormal", 0.0}, {"phiDepth", 0.0},
                                                       {"phiColor", 3e38}, {"phiNormal", 1e5}, {"phiDepth", 3e38}};
    for (const auto& [phi, value] : extremes)
        for (bool reference : {false, true}) {
            Harness h({{phi, value}, {"referenceStages", reference}}, noisyPixel, false, 40, 24);
            for (int frame = 0; frame < 6; ++frame) {
                h.run();
                for (const char* out : {"filtered", "variance", "estimate"})
                    EXPECT_TRUE(allFinite(h.field(out))) << phi << " reference " << reference << " " << out;
                for (const auto& hist : historyFields(h.graph))
                    EXPECT_TRUE(allFinite(h.field(hist))) << phi << " " << hist;
            }
        }
}

// Anti-lag (A-SVGF): a lighting step (the illumination falls to a quarter) that the temporal gradients report is
// followed within a few frames; without them (and without the history clamp) the history takes tens of frames to
// forget the old light. Where the gradients report no change, the output is bit for bit that of a graph without
// them. Without gradients the history clamp is on by default and follows the step too.
TEST(SVGF, TemporalGradientsFollowALightingStepWithinFourFrames) {
    const uint64_t step = 40;
    const auto light = [&](uint64_t frame) { return frame < step ? 1.f : 0.25f; };
    const GFn fn = [&](uint64_t frame, uint32_t x, uint32_t y) {
        GPixel p;
        const float n = 0.5f + hash01(frame, x, y);  // noisy samples of mean 1
        p.color = glm::vec4(glm::vec3(light(frame) * n), 1.f);
        p.albedo = glm::vec4(1.f);
        // Last frame's sample re-shaded now: the same noise, this frame's light.
        if (frame > 0) {
            const float m = 0.5f + hash01(frame - 1, x - x % 3, y - y % 3);
            p.gradient = glm::vec2(light(frame) * m, light(frame - 1) * m);
        }
        return p;
    };
    Harness with({}, fn, false, 32, 32, "SvgfGradientSource"), without({{"historyClamp", false}}, fn), clamped({{"clampSigma", 1.0}}, fn);
    auto meanOf = [](const Harness& h) {
        double sum = 0.0;
        for (uint32_t y = 0; y < 32; ++y)
            for (uint32_t x = 0; x < 32; ++x) sum += h.filtered(x, y).r;
        return sum / (32.0 * 32.0);
    };
    for (uint64_t f = 0; f < step; ++f) {
        with.run();
        without.run();
        ASSERT_EQ(meanOf(with), meanOf(without)) << "frame " << f << ": no change, no difference";
    }
    clamped.run(int(step));
    int withFrames = -1, withoutFrames = -1, clampedFrames = -1;
    for (int k = 0; k < 40; ++k) {
        with.run();
        without.run();
        clamped.run();
        // Within 10 % of the new level (the noise's mean is 1, so the level is 0.25).
        if (withFrames < 0 && std::abs(meanOf(with) - 0.25) < 0.025) withFrames = k;
        if (withoutFrames < 0 && std::abs(meanOf(without) - 0.25) < 0.025) withoutFrames = k;
        if (clampedFrames < 0 && std::abs(meanOf(clamped) - 0.25) < 0.025) clampedFrames = k;
    }
    std::printf("frames to within 10 %% after the step: with gradients %d, without %d, history clamp %d\n", withFrames,
                withoutFrames, clampedFrames);
    EXPECT_GE(withFrames, 0);
    EXPECT_LE(withFrames, 3) << "back within 10 % in at most 4 frames (the step's frame included)";
    EXPECT_TRUE(withoutFrames < 0 || withoutFrames > 8) << "without gradients the history lags";
    EXPECT_GE(clampedFrames, 0);
    EXPECT_LE(clampedFrames, 3) << "the history clamp: back within 10 % in at most 4 frames";
}

// With camera jitter the signal of pixel x is sampled at x + jitter and the history where last frame sampled: the
// reprojection shifts by the jitter's change. On a linear ramp the reprojected history then equals this frame's
// sample exactly (bilinear interpolation is exact on a ramp), so the temporal result is the sample itself; the
// unshifted history of the jitter-free motion vectors would be off by the ramp's slope times the jitter change.
TEST(SVGF, JitteredHistoryIsRegisteredWithTheSamples) {
    Camera camera;
    const float slope = 0.01f;
    const GFn fn = [&](uint64_t, uint32_t x, uint32_t y) {
        GPixel p;
        p.color = glm::vec4(glm::vec3(0.5f + slope * (float(x) + 0.5f + camera.jitter.x) +
                                      0.3f * slope * (float(y) + 0.5f + camera.jitter.y)),
                            1.f);
        return p;
    };
    Harness h({{"iterations", 0}}, fn);
    double worst = 0.0, slopeTimesJitter = 0.0;
    for (uint64_t f = 0; f < 12; ++f) {
        camera.prevJitter = camera.jitter;
        camera.jitter = Camera::jitterSample(JitterPattern::Halton, 8, f);
        h.run(1, &camera);
        if (f < 4) continue;
        slopeTimesJitter = std::max(slopeTimesJitter, double(slope * std::abs(camera.jitter.x - camera.prevJitter.x)));
        const auto estimate = h.field("estimate").view<glm::vec4>();
        // Away from the border, whose missing taps bend the history (and spread inward a pixel per frame).
        for (uint32_t y = 12; y < 20; ++y)
            for (uint32_t x = 12; x < 20; ++x)
                worst = std::max(worst, double(std::abs(estimate.at(x, y).r - fn(f, x, y).color.r)));
    }
    EXPECT_LT(worst, 2e-5) << "history and sample disagree: misregistered by the jitter";
    EXPECT_GT(slopeTimesJitter, 100 * 2e-5) << "the jitter moves the samples by far more than the tolerance";
}
