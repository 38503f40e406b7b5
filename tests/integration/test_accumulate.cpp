// AccumulatePass: exact means, float vs Kahan vs double on long sequences, maxFrames, resets (explicit, precision
// change, camera, instance and light motion, enable toggle), non-finite samples, determinism across thread counts,
// dumpable history, parameter independence of reflection. The per-pixel kernels on their own: passes/Accumulate/tests/.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <functional>
#include <glm/glm.hpp>
#include <glm/gtc/matrix_transform.hpp>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <set>
#include <string>
#include <vector>

#include "../../passes/Accumulate/AccumulateKernels.h"
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

using SampleFn = std::function<glm::vec4(uint64_t frame, uint32_t x, uint32_t y)>;

using SequencePass = test::FunctionSource;

/// The build's plugins (AccumulatePass, the test passes) plus Sequence.
PluginRegistry& registry() {
    return test::registryWithFunctionSource();
}

const char* const kPrecisions[] = {"float", "kahan", "double"};

const char* const kStateFields[] = {"sum", "sumExtra", "count", "frames"};

/// Source (Sequence) -> Accumulate, run one frame at a time.
struct Harness {
    explicit Harness(const nlohmann::json& params = nlohmann::json::object(), uint32_t width = 16, uint32_t height = 16,
                     std::vector<std::string> observe = {})
        : graph(describe(params), registry()) {
        CompileOptions options;
        options.width = width;
        options.height = height;
        options.observe = std::move(observe);
        graph.compile(options);
        source = dynamic_cast<SequencePass*>(graph.pass("Source"));
    }

    static GraphDesc describe(const nlohmann::json& params) {
        nlohmann::json g = {
            {"loom_graph", 1},
            {"name", "accumulate"},
            {"passes",
             {{{"name", "Source"}, {"type", "FunctionSource"}},
              {{"name", "Accumulate"}, {"type", "AccumulatePass"}, {"params", params}}}},
            {"edges", nlohmann::json::array({nlohmann::json::array({"Source.color", "Accumulate.src"})})},
            {"outputs", {"Accumulate.dst"}}};
        return parseGraph(g.dump());
    }

    /// Runs one frame; returns its index.
    uint64_t run() {
        FrameInfo f;
        f.frameIndex = nextFrame++;
        f.time = double(f.frameIndex) / 60.0;
        f.camera = camera;
        f.scene = scene;
        graph.execute(f);
        return f.frameIndex;
    }
    void run(int frames) {
        for (int i = 0; i < frames; ++i) run();
    }

    const Texture& field(const std::string& name) const {
        const Texture* t = graph.fieldTexture("Accumulate." + name);
        if (!t) throw std::runtime_error("no texture for Accumulate." + name);
        return *t;
    }
    glm::vec4 dst(uint32_t x, uint32_t y) const { return field("dst").view<glm::vec4>().at(x, y); }
    uint32_t count(uint32_t x, uint32_t y) const { return field("count").view<uint32_t>().at(x, y); }
    uint32_t frames() const { return field("frames").view<uint32_t>().at(0, 0); }
    double stat(const std::string& name) const {
        auto stats = graph.lastStats();
        auto pass = stats.find("Accumulate");
        if (pass == stats.end()) return std::nan("");
        auto it = pass->second.find(name);
        return it == pass->second.end() ? std::nan("") : it->second;
    }
    void set(const std::string& param, const nlohmann::json& value) {
        graph.setParam("Accumulate", param, value, "test");
    }

    RenderGraph graph;
    SequencePass* source = nullptr;
    uint64_t nextFrame = 0;
    const Camera* camera = nullptr;
    const Scene* scene = nullptr;
};

nlohmann::json withPrecision(const char* precision) {
    return {{"precision", precision}};
}

std::string str(const glm::vec4& v) {
    return "(" + std::to_string(v.x) + ", " + std::to_string(v.y) + ", " + std::to_string(v.z) + ", " +
           std::to_string(v.w) + ")";
}

/// Exact (bitwise for non-NaN) equality of two colours, with a readable failure.
::testing::AssertionResult sameColor(const glm::vec4& got, const glm::vec4& want) {
    for (int c = 0; c < 4; ++c)
        if (!(got[c] == want[c]))
            return ::testing::AssertionFailure() << "got " << str(got) << ", want " << str(want) << " (channel " << c
                                                 << " differs by " << double(got[c]) - double(want[c]) << ")";
    return ::testing::AssertionSuccess();
}

/// Every pixel of dst equals want(x, y) exactly.
::testing::AssertionResult dstEquals(const Harness& h, const std::function<glm::vec4(uint32_t, uint32_t)>& want) {
    const Texture& t = h.field("dst");
    for (uint32_t y = 0; y < t.height(); ++y)
        for (uint32_t x = 0; x < t.width(); ++x)
            if (auto r = sameColor(h.dst(x, y), want(x, y)); !r) return r << " at pixel (" << x << ", " << y << ")";
    return ::testing::AssertionSuccess();
}

bool allFinite(const Texture& t) {
    for (uint32_t y = 0; y < t.height(); ++y)
        for (uint32_t x = 0; x < t.width(); ++x)
            for (uint32_t c = 0; c < 4; ++c)
                if (!std::isfinite(t.texel(x, y, c))) return false;
    return true;
}

bool allZero(const Texture& t) {
    const size_t rowBytes = size_t(t.width()) * formatInfo(t.format()).bytesPerPixel;
    for (uint32_t y = 0; y < t.height(); ++y)
        for (size_t i = 0; i < rowBytes; ++i)
            if (t.row(y)[i] != std::byte{0}) return false;
    return true;
}

std::unique_ptr<Texture> copyOf(const Texture& t) {
    auto c = std::make_unique<Texture>(t.width(), t.height(), t.format());
    c->copyFrom(t);
    return c;
}

using test::hash01;

// ---------------------------------------------------------------------------------------------------------------
// Exact means

TEST(AccumulatePass, MeanOfConstantInputIsTheConstantEveryFrame) {
    // Dyadic values: every partial sum is exact even in float, so all precisions must return the constant.
    for (const char* precision : kPrecisions) {
        SCOPED_TRACE(precision);
        Harness h(withPrecision(precision));
        auto value = [](uint32_t x, uint32_t y) { return glm::vec4(0.75f, 1.5f + x, 3.25f * y, -0.125f); };
        h.source->fn = [&](uint64_t, uint32_t x, uint32_t y) { return value(x, y); };
        for (int frame = 0; frame < 64; ++frame) {
            h.run();
            ASSERT_TRUE(dstEquals(h, value)) << "frame " << frame;
        }
    }
    // Arbitrary values: float rounding makes a float sum drift, but the compensated and the double sum stay exact.
    for (const char* precision : {"kahan", "double"}) {
        SCOPED_TRACE(precision);
        Harness h(withPrecision(precision));
        auto value = [](uint32_t x, uint32_t y) {
            return glm::vec4(0.1f * float(x + 1), 0.3f + 0.01f * float(y), 1.f / 3.f, 12345.678f);
        };
        h.source->fn = [&](uint64_t, uint32_t x, uint32_t y) { return value(x, y); };
        for (int frame = 0; frame < 1000; ++frame) {
            h.run();
            ASSERT_TRUE(dstEquals(h, value)) << "frame " << frame;
        }
    }
}

TEST(AccumulatePass, MeanOfOneToNIsExactInDouble) {
    Harness h;  // default precision: double
    // Scales that are powers of two keep every sum and mean exactly representable.
    const glm::vec4 scale(1.f, 0.5f, 4.f, -2.f);
    h.source->fn = [&](uint64_t frame, uint32_t, uint32_t) { return scale * float(frame + 1); };
    for (uint32_t n = 1; n <= 3000; ++n) {
        h.run();
        const glm::vec4 want = scale * (float(n + 1) / 2.f);
        ASSERT_TRUE(dstEquals(h, [&](uint32_t, uint32_t) { return want; })) << "after " << n << " frames";
        ASSERT_EQ(h.count(5, 7), n);
        ASSERT_EQ(h.frames(), n);
        ASSERT_EQ(h.stat("frames"), double(n));
    }
}

/// Max absolute error of each of three accumulators (float, kahan, double) fed the same sequence, against the mean
/// computed exactly (in long double from the very float values the source emitted).
std::map<std::string, double> precisionErrors(const SampleFn& fn, int frames, uint32_t size) {
    nlohmann::json passes = {{{"name", "Source"}, {"type", "FunctionSource"}}};
    nlohmann::json edges = nlohmann::json::array(), outputs = nlohmann::json::array();
    for (const char* precision : kPrecisions) {
        const std::string name = std::string("Acc_") + precision;
        passes.push_back({{"name", name}, {"type", "AccumulatePass"}, {"params", {{"precision", precision}}}});
        edges.push_back(nlohmann::json::array({"Source.color", name + ".src"}));
        outputs.push_back(name + ".dst");
    }
    nlohmann::json g = {
        {"loom_graph", 1}, {"name", "precision"}, {"passes", passes}, {"edges", edges}, {"outputs", outputs}};
    RenderGraph graph(parseGraph(g.dump()), registry());
    CompileOptions options;
    options.width = options.height = size;
    graph.compile(options);
    dynamic_cast<SequencePass*>(graph.pass("Source"))->fn = fn;

    std::vector<glm::dvec4> exact(size_t(size) * size);
    std::vector<long double> sums(size_t(size) * size * 4, 0.0L);
    for (int f = 0; f < frames; ++f) {
        FrameInfo info;
        info.frameIndex = uint64_t(f);
        graph.execute(info);
        for (uint32_t y = 0; y < size; ++y)
            for (uint32_t x = 0; x < size; ++x) {
                const glm::vec4 v = fn(uint64_t(f), x, y);
                for (int c = 0; c < 4; ++c) sums[(size_t(y) * size + x) * 4 + c] += v[c];
            }
    }
    std::map<std::string, double> errors;
    for (const char* precision : kPrecisions) {
        auto dst = graph.fieldTexture(std::string("Acc_") + precision + ".dst")->view<glm::vec4>();
        double worst = 0.0;
        for (uint32_t y = 0; y < size; ++y)
            for (uint32_t x = 0; x < size; ++x)
                for (int c = 0; c < 4; ++c) {
                    const long double mean = sums[(size_t(y) * size + x) * 4 + c] / frames;
                    worst = std::max(worst, double(std::fabs((long double)dst.at(x, y)[c] - mean)));
                }
        errors[precision] = worst;
    }
    return errors;
}

TEST(AccumulatePass, KahanAndDoubleBeatFloatOnALargeValueFollowedBySmallOnes) {
    // Frame 0 brings 1e8, then 999 frames of 1: in float, 1e8 + 1 rounds back to 1e8 (ulp 8), so every small
    // sample is lost and the mean is off by about 1. The exact mean, 100000.999, is 1/8 ulp from a float.
    auto errors = precisionErrors(
        [](uint64_t frame, uint32_t, uint32_t) { return frame == 0 ? glm::vec4(1e8f) : glm::vec4(1.f); }, 1000, 16);
    const double ulp = 1.0 / 128.0;  // float spacing at 1e5
    EXPECT_GT(errors["float"], 0.9);
    EXPECT_LE(errors["kahan"], ulp / 2);
    EXPECT_LE(errors["double"], ulp / 2);
}

TEST(AccumulatePass, KahanAndDoubleBeatFloatOnLongNoisySequences) {
    // 10^4 frames of 1 + noise in [0, 1e-3): the float sum reaches 10^4, where its spacing (2^-10) is coarser than
    // the noise, so each addition rounds. Kahan and double leave only the final rounding to a float near 1.
    auto errors = precisionErrors(
        [](uint64_t frame, uint32_t x, uint32_t y) {
            return glm::vec4(1.f + 1e-3f * hash01(frame, x, y), 1.f + 1e-3f * hash01(frame, x + 100, y),
                             1.f + 1e-4f * hash01(frame, x, y + 100), 1.f);
        },
        10000, 16);
    const double halfUlp = std::ldexp(1.0, -24);
    SCOPED_TRACE("float " + std::to_string(errors["float"]) + ", kahan " + std::to_string(errors["kahan"]) +
                 ", double " + std::to_string(errors["double"]));
    EXPECT_LE(errors["kahan"], 2 * halfUlp);
    EXPECT_LE(errors["double"], halfUlp);
    EXPECT_GT(errors["float"], 20 * errors["kahan"]);
    EXPECT_GT(errors["float"], 20 * errors["double"]);
}

// ---------------------------------------------------------------------------------------------------------------
// maxFrames

TEST(AccumulatePass, MaxFramesFreezesTheMeanOfTheFirstFrames) {
    for (const char* precision : kPrecisions) {
        SCOPED_TRACE(precision);
        Harness h(nlohmann::json{{"precision", precision}, {"maxFrames", 5}});
        h.source->fn = [](uint64_t frame, uint32_t x, uint32_t) { return glm::vec4(float(frame + 1) + float(x)); };
        h.run(5);
        auto meanOfFirst5 = [](uint32_t x, uint32_t) { return glm::vec4(3.f + float(x)); };
        ASSERT_TRUE(dstEquals(h, meanOfFirst5));
        for (int i = 0; i < 10; ++i) {
            h.run();
            ASSERT_TRUE(dstEquals(h, meanOfFirst5)) << "frozen frame " << i;
            EXPECT_EQ(h.stat("frames"), 5);
            EXPECT_EQ(h.count(3, 3), 5u);
        }
        // Raising the limit continues the same accumulation: frames 1..5 and now 16.
        h.set("maxFrames", 6);
        h.run();
        ASSERT_TRUE(dstEquals(h, [](uint32_t x, uint32_t) { return glm::vec4(float((31.0 + 6.0 * x) / 6.0)); }));
        EXPECT_EQ(h.stat("frames"), 6);
        EXPECT_EQ(h.stat("reset"), 0);
        // Lowering it below the frames already in the mean restarts, so the output is again the mean of the
        // first maxFrames frames (17 and 18), then freezes.
        h.set("maxFrames", 2);
        h.run(2);
        ASSERT_TRUE(dstEquals(h, [](uint32_t x, uint32_t) { return glm::vec4(17.5f + float(x)); }));
        h.run(3);
        ASSERT_TRUE(dstEquals(h, [](uint32_t x, uint32_t) { return glm::vec4(17.5f + float(x)); }));
        EXPECT_EQ(h.stat("frames"), 2);
        // 0 = unlimited: accumulation resumes.
        h.set("maxFrames", 0);
        h.run();
        ASSERT_TRUE(dstEquals(h, [](uint32_t x, uint32_t) { return glm::vec4(19.f + float(x)); }));  // 17, 18, 22
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Resets

TEST(AccumulatePass, ResetHistoryRestartsTheMean) {
    for (const char* precision : kPrecisions) {
        SCOPED_TRACE(precision);
        Harness h(withPrecision(precision));
        h.source->fn = [](uint64_t frame, uint32_t, uint32_t) { return glm::vec4(float(frame + 1)); };
        h.run(4);
        ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(2.5f); }));
        EXPECT_EQ(h.stat("reset"), 0);
        h.graph.resetHistory();
        h.run();  // sample 5
        EXPECT_EQ(h.stat("reset"), 1);
        EXPECT_EQ(h.stat("frames"), 1);
        ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(5.f); }));
        h.run();  // sample 6
        ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(5.5f); }));
        EXPECT_EQ(h.count(0, 0), 2u);
    }
}

TEST(AccumulatePass, ChangingPrecisionRestartsAndClearsTheOldState) {
    Harness h;  // double
    h.source->fn = [](uint64_t frame, uint32_t, uint32_t) { return glm::vec4(float(frame + 1)); };
    h.run(4);
    EXPECT_FALSE(allZero(h.field("sumExtra")));
    h.set("precision", "kahan");
    h.run();  // sample 5
    EXPECT_EQ(h.stat("reset"), 1);
    ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(5.f); }));
    h.run();  // sample 6: both sides of the history pairs have now been rewritten
    ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(5.5f); }));
    // Kahan keeps the float sum's bits where double kept R and G, and the compensation (exact here: zero) where
    // it kept B and A.
    EXPECT_EQ(h.field("sum").view<glm::uvec4>().at(1, 1), accumulate::floatBits(glm::vec4(11.f)));
    EXPECT_TRUE(allZero(h.field("sumExtra")));

    h.set("precision", "float");
    h.run(3);  // samples 7, 8, 9 (sample 7 restarts)
    ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(8.f); }));
    EXPECT_TRUE(allZero(h.field("sumExtra")));
    h.run();
    EXPECT_TRUE(allZero(h.field("sumExtra"))) << "the other side of the pair";

    // Setting the same value again is not a change.
    h.set("precision", "float");
    h.run();
    EXPECT_EQ(h.stat("reset"), 0);
    EXPECT_EQ(h.stat("frames"), 5);
}

TEST(AccumulatePass, CameraMotionRestartsOnlyWithAutoReset) {
    for (bool autoReset : {true, false}) {
        SCOPED_TRACE(autoReset ? "autoReset" : "no autoReset");
        Camera camera;
        camera.world = glm::translate(glm::mat4(1.f), glm::vec3(0.f, 1.f, 5.f));
        camera.prevWorld = camera.world;
        Harness h(nlohmann::json{{"autoReset", autoReset}});
        h.camera = &camera;
        h.source->fn = [](uint64_t frame, uint32_t, uint32_t) { return glm::vec4(float(frame + 1)); };
        h.run(3);  // static: 1, 2, 3
        ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(2.f); }));

        // Jitter alone is not motion.
        camera.prevJitter = camera.jitter;
        camera.jitter = glm::vec2(0.25f, -0.25f);
        h.run();  // 4
        ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(2.5f); }));

        camera.prevWorld = camera.world;
        camera.world = glm::translate(camera.world, glm::vec3(0.01f, 0.f, 0.f));
        h.run();  // 5, moving
        EXPECT_EQ(h.stat("reset"), autoReset ? 1 : 0);
        ASSERT_TRUE(dstEquals(h, [&](uint32_t, uint32_t) { return glm::vec4(autoReset ? 5.f : 3.f); }));

        camera.prevWorld = camera.world;  // still again
        h.run();                          // 6
        ASSERT_TRUE(dstEquals(h, [&](uint32_t, uint32_t) { return glm::vec4(autoReset ? 5.5f : 3.5f); }));
    }
}

TEST(AccumulatePass, InstanceMotionRestartsWithAutoReset) {
    Scene scene;
    scene.instances.resize(3);
    Harness h;
    h.scene = &scene;  // no camera: only instances can trigger a reset
    h.source->fn = [](uint64_t frame, uint32_t, uint32_t) { return glm::vec4(float(frame + 1)); };
    h.run(2);
    ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(1.5f); }));
    scene.instances[2].world = glm::translate(glm::mat4(1.f), glm::vec3(0.f, 0.5f, 0.f));
    h.run();  // 3, instance 2 moved this frame
    EXPECT_EQ(h.stat("reset"), 1);
    ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(3.f); }));
    scene.instances[2].prevWorld = scene.instances[2].world;
    h.run();  // 4
    ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(3.5f); }));
}

TEST(AccumulatePass, PunctualLightMotionRestartsWithAutoReset) {
    // A light has no previous pose in the scene: the pass compares with the one it saw last frame.
    Scene scene;
    scene.lights.resize(2);
    Harness h;
    h.scene = &scene;
    h.source->fn = [](uint64_t frame, uint32_t, uint32_t) { return glm::vec4(float(frame + 1)); };
    h.run(2);
    ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(1.5f); }));
    scene.lights[1].position = glm::vec3(0.f, 0.5f, 0.f);
    h.run();  // 3, light 1 moved this frame
    EXPECT_EQ(h.stat("reset"), 1);
    ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(3.f); }));
    h.run();  // 4, still
    ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(3.5f); }));
    scene.lights[0].direction = glm::vec3(0.f, -1.f, 0.f);
    h.run();  // 5, light 0 turned
    EXPECT_EQ(h.stat("reset"), 1);
    ASSERT_TRUE(dstEquals(h, [](uint32_t, uint32_t) { return glm::vec4(5.f); }));
}

TEST(AccumulatePass, DisabledPassesSourceThroughAndRestartsWhenEnabledAgain) {
    Harness h;
    h.source->fn = [](uint64_t frame, uint32_t x, uint32_t y) {
        // A NaN passes through untouched: disabled means a copy.
        return x == 2 && y == 2 ? glm::vec4(std::numeric_limits<float>::quiet_NaN()) : glm::vec4(float(frame + 1));
    };
    h.run(3);
    h.set("enabled", false);
    h.run();  // 4
    const Texture& dst = h.field("dst");
    EXPECT_TRUE(std::isnan(dst.texel(2, 2, 0)));
    EXPECT_EQ(dst.texel(0, 0, 0), 4.f);
    EXPECT_EQ(h.stat("frames"), 0);
    for (const char* field : kStateFields) EXPECT_TRUE(allZero(h.field(field))) << field;
    h.run();  // 5
    EXPECT_EQ(dst.texel(1, 0, 0), 5.f);
    h.set("enabled", true);
    h.run();  // 6: a new accumulation
    EXPECT_EQ(h.stat("reset"), 1);
    EXPECT_EQ(dst.texel(1, 0, 0), 6.f);
    h.run();  // 7
    EXPECT_EQ(dst.texel(1, 0, 0), 6.5f);
    EXPECT_EQ(dst.texel(2, 2, 0), 0.f) << "no finite sample yet at the NaN pixel";
}

// ---------------------------------------------------------------------------------------------------------------
// Non-finite samples

TEST(AccumulatePass, NonFiniteSamplesAreSkippedAndCounted) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    for (const char* precision : kPrecisions) {
        SCOPED_TRACE(precision);
        Harness h(withPrecision(precision));
        h.source->fn = [&](uint64_t frame, uint32_t x, uint32_t y) {
            glm::vec4 v(float(frame + 1));
            if (frame == 0 && x == 0 && y == 0) v = glm::vec4(-inf);
            if (frame == 2 && x == 3 && y == 5) v.r = nan;
            if (frame == 4 && x == 7 && y == 1) v.g = inf;  // one bad channel drops the whole sample
            return v;
        };
        const double expectedSkips[] = {1, 0, 1, 0, 1, 0};
        for (int frame = 0; frame < 6; ++frame) {
            h.run();
            ASSERT_TRUE(allFinite(h.field("dst"))) << "frame " << frame;
            EXPECT_EQ(h.stat("nonFinite"), expectedSkips[frame]) << "frame " << frame;
            EXPECT_EQ(h.stat("frames"), frame + 1);
            if (frame == 0) {
                EXPECT_TRUE(sameColor(h.dst(0, 0), glm::vec4(0.f))) << "no finite sample yet";
            }
        }
        // Means of the finite samples only.
        EXPECT_TRUE(dstEquals(h, [](uint32_t x, uint32_t y) {
            if (x == 0 && y == 0) return glm::vec4(20.f / 5.f);  // 2..6
            if (x == 3 && y == 5) return glm::vec4(18.f / 5.f);  // 1, 2, 4, 5, 6
            if (x == 7 && y == 1) return glm::vec4(16.f / 5.f);  // 1..4, 6
            return glm::vec4(3.5f);
        }));
        EXPECT_EQ(h.count(0, 0), 5u);
        EXPECT_EQ(h.count(3, 5), 5u);
        EXPECT_EQ(h.count(7, 1), 5u);
        EXPECT_EQ(h.count(8, 8), 6u);
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Determinism, observation, reflection

TEST(AccumulatePass, IdenticalResultsForAnyThreadCount) {
    const float nan = std::numeric_limits<float>::quiet_NaN();
    const SampleFn noisy = [&](uint64_t frame, uint32_t x, uint32_t y) {
        if (hash01(frame, x + 7, y) < 0.01f) return glm::vec4(nan);
        return glm::vec4(100.f * hash01(frame, x, y), hash01(frame, x, y + 64), 1e4f * hash01(frame, y, x), 1.f);
    };
    for (const char* precision : kPrecisions) {
        SCOPED_TRACE(precision);
        std::map<std::string, std::unique_ptr<Texture>> results[2];
        double skipped[2] = {0, 0};
        for (int run = 0; run < 2; ++run) {
            ThreadLimit limit(run == 0 ? 1 : 2);
            Harness h(withPrecision(precision), 64, 64);  // 4 tiles of 32x32
            h.source->fn = noisy;
            for (int frame = 0; frame < 30; ++frame) {
                h.run();
                skipped[run] += h.stat("nonFinite");
            }
            results[run]["dst"] = copyOf(h.field("dst"));
            for (const char* field : kStateFields) results[run][field] = copyOf(h.field(field));
        }
        EXPECT_GT(skipped[0], 0);
        EXPECT_EQ(skipped[0], skipped[1]);
        for (const auto& [name, texture] : results[0]) EXPECT_TRUE(texture->samePixels(*results[1][name])) << name;
    }
}

// The state goes through the two packed uint fields every frame: the pass's means must be those of the per-pixel
// kernels run on a state kept in plain float and double members, bit for bit, in every precision.
TEST(AccumulatePass, PackedStateGivesTheKernelsMeansBitForBit) {
    const SampleFn noisy = [](uint64_t frame, uint32_t x, uint32_t y) {
        return glm::vec4(1e3f * hash01(frame, x, y), hash01(frame, x, y + 64), 1e-3f * hash01(frame, y, x),
                         1e6f * hash01(frame + 9, x, y));
    };
    const std::pair<const char*, accumulate::Precision> precisions[] = {{"float", accumulate::Precision::Float},
                                                                         {"kahan", accumulate::Precision::Kahan},
                                                                         {"double", accumulate::Precision::Double}};
    for (const auto& [name, precision] : precisions) {
        SCOPED_TRACE(name);
        Harness h(withPrecision(name), 16, 8);
        h.source->fn = noisy;
        std::vector<accumulate::PixelState> states(16 * 8);
        for (uint64_t frame = 0; frame < 40; ++frame) {
            h.run();
            for (uint32_t y = 0; y < 8; ++y)
                for (uint32_t x = 0; x < 16; ++x) accumulate::addSample(precision, states[y * 16 + x], noisy(frame, x, y));
        }
        EXPECT_TRUE(dstEquals(h, [&](uint32_t x, uint32_t y) { return accumulate::mean(precision, states[y * 16 + x]); }));
    }
}

TEST(AccumulatePass, HistoryFieldsCanBeObservedAndHoldTheState) {
    for (const char* precision : kPrecisions) {
        SCOPED_TRACE(precision);
        Harness h(withPrecision(precision), 16, 16, {"Accumulate.*"});
        std::set<std::string> seen;
        std::map<std::string, std::unique_ptr<Texture>> last;
        h.graph.setFieldObserver(
            [&](const FrameInfo&, const std::string& pass, const std::string& field, const Texture& t) {
                EXPECT_EQ(pass, "Accumulate");
                seen.insert(field);
                last[field] = copyOf(t);
            });
        h.source->fn = [](uint64_t frame, uint32_t x, uint32_t) { return glm::vec4(0.5f + float(x)); };
        h.run(3);
        EXPECT_EQ(seen, (std::set<std::string>{"src", "dst", "sum", "sumExtra", "count", "frames", "partialSumRG",
                                               "partialSumBA", "partialCount"}));
        // The partial outputs (for merging shards) hold the state as double sums and counts in every precision:
        // three samples of 4.5 at x = 4, so dst = partialSum / partialCount.
        EXPECT_EQ(last["partialCount"]->view<uint32_t>().at(4, 2), 3u);
        EXPECT_EQ(accumulate::unpackDoubleSum(last["partialSumRG"]->view<glm::uvec4>().at(4, 2),
                                              last["partialSumBA"]->view<glm::uvec4>().at(4, 2)),
                  glm::dvec4(13.5));
        // The dumped state: three samples of 0.5 + x.
        EXPECT_EQ(last["count"]->view<uint32_t>().at(4, 2), 3u);
        EXPECT_EQ(last["frames"]->width(), 1u);
        EXPECT_EQ(last["frames"]->view<uint32_t>().at(0, 0), 3u);
        const glm::uvec4 sum = last["sum"]->view<glm::uvec4>().at(4, 2);
        if (std::string(precision) == "double") {
            EXPECT_EQ(accumulate::unpackDoubleSum(sum, last["sumExtra"]->view<glm::uvec4>().at(4, 2)),
                      glm::dvec4(13.5));
        } else {
            EXPECT_EQ(accumulate::bitsToFloat(sum), glm::vec4(3.f * 4.5f));
            EXPECT_TRUE(allZero(*last["sumExtra"])) << "no rounding error to compensate";
        }
    }
}

TEST(AccumulatePass, ReflectionAndAllocationDoNotDependOnParameters) {
    auto fieldsWith = [](const nlohmann::json& params) {
        return test::reflectedFields(registry(), "AccumulatePass", params);
    };
    const auto reference = fieldsWith(nlohmann::json::object());
    EXPECT_EQ(fieldsWith({{"precision", "float"}}), reference);
    EXPECT_EQ(fieldsWith({{"precision", "kahan"}, {"maxFrames", 8}, {"autoReset", false}, {"enabled", false}}),
              reference);

    // Changing parameters on a compiled graph keeps its plan and its textures.
    Harness h;
    h.source->fn = [](uint64_t, uint32_t, uint32_t) { return glm::vec4(1.f); };
    h.run(2);
    std::map<std::string, const Texture*> before;
    for (const char* field : kStateFields) before[field] = h.graph.fieldTexture(std::string("Accumulate.") + field);
    const size_t historyBytes = h.graph.plan().historyBytes;
    h.set("precision", "float");
    h.set("maxFrames", 3);
    h.run();
    EXPECT_TRUE(h.graph.compiled());
    EXPECT_EQ(h.graph.plan().historyBytes, historyBytes);
    for (const char* field : kStateFields)
        EXPECT_EQ(h.graph.fieldTexture(std::string("Accumulate.") + field), before[field]) << field;
}

TEST(AccumulatePass, RejectsANegativeMaxFrames) {
    Harness h;
    EXPECT_THROW(h.set("maxFrames", -1), std::exception);
    EXPECT_THROW(h.set("precision", "half"), std::exception);
}

}  // namespace
