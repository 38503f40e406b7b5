// ToneMap: each operator against its closed form (written here independently), exposure compensation, auto
// exposure (log-average luminance and its exponential adaptation against the closed form), the exact sRGB encoding,
// non-finite inputs, the optional dstFloat output, determinism and parameter-independent reflection. The kernels on
// their own: passes/ToneMap/tests/.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <functional>
#include <glm/glm.hpp>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/Graph.h"
#include "loom/KernelMath.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"
#include "loom/RenderGraph.h"
#include "loom/SrgbEncode.h"
#include "loom/Texture.h"

using namespace loom;

namespace {

using ImageFn = std::function<glm::vec4(uint64_t frame, uint32_t x, uint32_t y)>;

using ImageSource = test::FunctionSource;

PluginRegistry& registry() {
    return test::registryWithFunctionSource();
}

// Closed forms, in double, independent of the kernel header.
double srgbExact(double v) {
    return v <= 0.0031308 ? 12.92 * v : 1.055 * std::pow(v, 1.0 / 2.4) - 0.055;
}
int srgbCode(double v) {
    return int(std::floor(255.0 * srgbExact(std::clamp(v, 0.0, 1.0)) + 0.5));
}
double hable(double x) {
    const double A = 0.15, B = 0.50, C = 0.10, D = 0.20, E = 0.02, F = 0.30;
    return ((x * (A * x + C * B) + D * E) / (x * (A * x + B) + D * F)) - E / F;
}
double closedForm(const std::string& op, double v, double white = 4.0) {
    double r = v;
    if (op == "reinhard") r = v / (1.0 + v);
    if (op == "modifiedReinhard") r = v * (1.0 + v / (white * white)) / (1.0 + v);
    if (op == "aces") r = (v * (2.51 * v + 0.03)) / (v * (2.43 * v + 0.59) + 0.14);
    if (op == "hable") r = hable(v) / hable(11.2);
    return std::clamp(r, 0.0, 1.0);
}
double rec709(const glm::vec4& c) {
    return kRec709R * c.x + kRec709G * c.y + kRec709B * c.z;
}

std::unique_ptr<Texture> copyOf(const Texture& t) {
    auto c = std::make_unique<Texture>(t.width(), t.height(), t.format());
    c->copyFrom(t);
    return c;
}

const char* const kOperators[] = {"linear", "reinhard", "modifiedReinhard", "aces", "hable"};

/// ImageSource -> ToneMap, one frame at a time.
struct Harness {
    explicit Harness(const nlohmann::json& params, bool withFloat = true, uint32_t width = 16, uint32_t height = 16)
        : graph(describe(params, withFloat), registry()) {
        CompileOptions o;
        o.width = width;
        o.height = height;
        graph.compile(o);
        source = dynamic_cast<ImageSource*>(graph.pass("Source"));
    }
    static GraphDesc describe(const nlohmann::json& params, bool withFloat) {
        nlohmann::json outputs = {"ToneMap.dst"};
        if (withFloat) outputs.push_back("ToneMap.dstFloat");
        nlohmann::json g = {{"loom_graph", 1},
                            {"name", "tonemap"},
                            {"passes",
                             {{{"name", "Source"}, {"type", "FunctionSource"}},
                              {{"name", "ToneMap"}, {"type", "ToneMap"}, {"params", params}}}},
                            {"edges", nlohmann::json::array({nlohmann::json::array({"Source.color", "ToneMap.src"})})},
                            {"outputs", outputs}};
        return parseGraph(g.dump());
    }
    void run(double dt = 1.0 / 60.0) {
        FrameInfo f;
        f.frameIndex = frame++;
        f.time = time;
        time += dt;
        graph.execute(f);
    }
    const Texture& field(const std::string& name) const {
        const Texture* t = graph.fieldTexture("ToneMap." + name);
        if (!t) throw std::runtime_error("no texture for ToneMap." + name);
        return *t;
    }
    glm::vec4 mapped(uint32_t x, uint32_t y) const { return field("dstFloat").view<glm::vec4>().at(x, y); }
    glm::uvec4 code(uint32_t x, uint32_t y) const {
        const uint32_t p = field("dst").view<uint32_t>().at(x, y);
        return glm::uvec4(p & 255u, (p >> 8) & 255u, (p >> 16) & 255u, p >> 24);
    }
    double stat(const std::string& name) const { return graph.lastStats().at("ToneMap").at(name); }

    RenderGraph graph;
    ImageSource* source = nullptr;
    uint64_t frame = 0;
    double time = 0.0;
};

/// A 16x16 image whose pixel i = y * 16 + x has value values[i % values.size()] in every colour channel.
ImageFn sweep(const std::vector<float>& values) {
    return [values](uint64_t, uint32_t x, uint32_t y) {
        const float v = values[(y * 16 + x) % values.size()];
        return glm::vec4(v, v, v, 1.f);
    };
}

const std::vector<float> kTestValues = {0.f, 1e-4f, 0.01f, 0.1f, 0.18f, 0.5f, 1.f, 2.f, 4.f, 11.2f, 50.f, 1000.f};

}  // namespace

// ---------------------------------------------------------------------------------------------------------------
// Operators and exposure

TEST(ToneMap, EveryOperatorMatchesItsClosedForm) {
    for (const char* op : kOperators) {
        for (float ev : {0.f, -1.5f, 2.f}) {
            SCOPED_TRACE(std::string(op) + " EV " + std::to_string(ev));
            Harness h(nlohmann::json{{"operator", op}, {"exposure", ev}, {"whitePoint", 3.f}});
            h.source->fn = sweep(kTestValues);
            h.run();
            for (size_t i = 0; i < kTestValues.size(); ++i) {
                const uint32_t x = uint32_t(i % 16), y = uint32_t(i / 16);
                const double want = closedForm(op, double(kTestValues[i]) * std::exp2(double(ev)), 3.0);
                const glm::vec4 got = h.mapped(x, y);
                EXPECT_NEAR(got.x, want, 2e-6 + 2e-6 * want) << "input " << kTestValues[i];
                EXPECT_EQ(got.x, got.y);
                EXPECT_EQ(got.x, got.z);
                EXPECT_EQ(got.w, 1.f);
                EXPECT_EQ(int(h.code(x, y).x), srgbCode(double(got.x))) << "input " << kTestValues[i];
                EXPECT_EQ(h.code(x, y).w, 255u);
            }
        }
    }
}

TEST(ToneMap, OneEvEqualsDoublingTheInput) {
    const std::vector<float> values = {0.f, 1e-3f, 0.03f, 0.2f, 0.37f, 0.5f, 0.7f, 3.f};
    Harness plus(nlohmann::json{{"operator", "linear"}, {"exposure", 1.f}});
    Harness doubled(nlohmann::json{{"operator", "linear"}});
    plus.source->fn = sweep(values);
    doubled.source->fn = [&](uint64_t f, uint32_t x, uint32_t y) {
        return sweep(values)(f, x, y) * glm::vec4(2, 2, 2, 1);
    };
    plus.run();
    doubled.run();
    EXPECT_TRUE(plus.field("dstFloat").samePixels(doubled.field("dstFloat")));
    EXPECT_TRUE(plus.field("dst").samePixels(doubled.field("dst")));
    EXPECT_EQ(plus.mapped(3, 0).x, 0.4f);
}

// ---------------------------------------------------------------------------------------------------------------
// Auto exposure

TEST(ToneMap, AutoExposureMapsTheLogAverageToTheKey) {
    const glm::vec4 color(0.8f, 2.f, 0.4f, 1.f);
    const double lum = rec709(color);
    Harness h(nlohmann::json{{"operator", "linear"}, {"autoExposure", true}, {"key", 0.25f}, {"adaptationTime", 0.5f}});
    h.source->fn = [&](uint64_t, uint32_t, uint32_t) { return color; };
    const double dt = 0.04, tau = 0.5;
    h.run(dt);  // frame k runs at time k dt
    // First frame: immediately adapted to the geometric mean of (epsilon + Y), which for a constant image is it.
    const double logAverage = 1e-4 + lum;
    EXPECT_NEAR(h.stat("measuredLuminance"), logAverage, 2e-6 * logAverage);
    EXPECT_NEAR(h.stat("adaptedLuminance"), logAverage, 2e-6 * logAverage);
    EXPECT_NEAR(h.stat("exposure"), 0.25 / logAverage, 1e-5);
    EXPECT_NEAR(h.mapped(5, 5).y, 2.0 * 0.25 / logAverage, 1e-5);
    // The state is in the history field.
    const glm::vec4 state = h.field("adaptedLuminance").view<glm::vec4>().at(0, 0);
    EXPECT_EQ(double(state.x), h.stat("adaptedLuminance"));

    // Half the image 16x brighter: the geometric mean of the two (epsilon included) is the new target.
    h.source->fn = [&](uint64_t, uint32_t x, uint32_t) { return x < 8 ? color * glm::vec4(16, 16, 16, 1) : color; };
    const double target = std::sqrt((1e-4 + 16.0 * lum) * (1e-4 + lum));
    // While adapting, frame k is exposed by the luminance adapted up to frame k - 1 and then measured (one read of
    // the input); the adapted value follows target + (start - target) exp(-t / tau).
    double previous = logAverage;
    for (int k = 1; k <= 30; ++k) {
        h.run(dt);
        const double want = target + (logAverage - target) * std::exp(-double(k) * dt / tau);
        ASSERT_NEAR(h.stat("measuredLuminance"), target, 2e-6 * target) << "frame " << k;
        ASSERT_NEAR(h.stat("adaptedLuminance"), want, 1e-5 * want) << "frame " << k;
        ASSERT_NEAR(h.stat("exposure"), 0.25 / previous, 1e-5 * (0.25 / previous)) << "frame " << k;
        ASSERT_NEAR(h.mapped(12, 3).z, 0.4 * 0.25 / previous, 1e-5) << "frame " << k;
        previous = want;
    }
    // After 30 frames = 1.2 s = 2.4 tau: within exp(-2.4) of the way; it keeps converging to key / target.
    for (int k = 0; k < 200; ++k) h.run(dt);
    EXPECT_NEAR(h.stat("exposure"), 0.25 / target, 1e-5 * 0.25 / target);

    // adaptationTime 0: this frame is measured first and exposed by its own log-average.
    h.graph.setParam("ToneMap", "adaptationTime", 0.f, "test");
    h.source->fn = [&](uint64_t, uint32_t, uint32_t) { return color; };
    h.run(dt);
    EXPECT_NEAR(h.stat("exposure"), 0.25 / logAverage, 1e-5 * 0.25 / logAverage);
    h.graph.setParam("ToneMap", "adaptationTime", 0.5f, "test");

    // A history reset adapts immediately again.
    h.graph.resetHistory();
    h.source->fn = [&](uint64_t, uint32_t, uint32_t) { return color; };
    h.run(dt);
    EXPECT_NEAR(h.stat("adaptedLuminance"), logAverage, 2e-6 * logAverage);
}

TEST(ToneMap, AutoExposureIgnoresNonFinitePixels) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    Harness h(nlohmann::json{{"autoExposure", true}, {"adaptationTime", 0.f}});
    h.source->fn = [&](uint64_t, uint32_t x, uint32_t y) {
        if (x == 3 && y == 2) return glm::vec4(nan, 1.f, 1.f, 1.f);
        if (x == 9 && y == 12) return glm::vec4(1.f, inf, 1.f, 1.f);
        return glm::vec4(0.5f, 0.5f, 0.5f, 1.f);
    };
    h.run();
    EXPECT_NEAR(h.stat("measuredLuminance"), 0.5 + 1e-4, 2e-6);
    EXPECT_EQ(h.stat("nonFinite"), 2);
    // Every pixel non-finite: nothing to measure, the exposure falls back to 1 (adapted = key).
    h.source->fn = [&](uint64_t, uint32_t, uint32_t) { return glm::vec4(nan); };
    h.graph.resetHistory();
    h.run();
    EXPECT_EQ(h.stat("exposure"), 1.0);
    EXPECT_EQ(h.code(0, 0), glm::uvec4(0u));
}

// The log-average is measured on every 4th row (y % 4 == 0), the first frame's measurement and the one made
// while adapting alike.
TEST(ToneMap, AutoExposureMeasuresEveryFourthRow) {
    Harness h(nlohmann::json{{"autoExposure", true}, {"adaptationTime", 1.f}}, true, 16, 18);
    h.source->fn = [](uint64_t, uint32_t, uint32_t y) {
        return y % 4 == 0 ? glm::vec4(0.5f, 0.5f, 0.5f, 1.f) : glm::vec4(8.f, 8.f, 8.f, 1.f);
    };
    for (int frame = 0; frame < 3; ++frame) {
        h.run();
        EXPECT_NEAR(h.stat("measuredLuminance"), 0.5 + 1e-4, 2e-6) << "frame " << frame;
    }
}

// ---------------------------------------------------------------------------------------------------------------
// sRGB encoding

TEST(ToneMap, SrgbEncodingIsExactAtKnownPoints) {
    SrgbEncodeTable table;
    buildSrgbEncodeTable(table);
    auto code = [&](float v) { return encodeSrgb8(table, v); };
    EXPECT_EQ(code(0.f), 0u);
    EXPECT_EQ(code(1.f), 255u);
    // 0.5 linear: 1.055 * 0.5^(1/2.4) - 0.055 = 0.7353569, * 255 = 187.516 -> 188.
    EXPECT_EQ(code(0.5f), 188u);
    EXPECT_NEAR(255.0 * srgbExact(0.5), 187.516, 1e-3);
    // Mid grey 0.18 -> 0.4613561 * 255 = 117.65 -> 118.
    EXPECT_EQ(code(0.18f), 118u);
    // The 127 / 128 boundary (sRGB 127.5 / 255) lies at linear 0.2140411405: 0.214041 itself encodes to
    // 127.49996 and rounds down; the next floats up reach 127.500001 -> 128. Linear 0.2158605 is sRGB 128 / 255.
    EXPECT_EQ(code(0.214041f), 127u);
    EXPECT_NEAR(255.0 * srgbExact(double(0.214041f)), 127.49996, 1e-5);
    EXPECT_EQ(code(0.21404114f), 128u);
    EXPECT_EQ(code(0.2158605f), 128u);
    // The linear segment up to 0.0031308 (12.92 * 0.0031308 * 255 = 10.31 -> 10) and just past it.
    EXPECT_EQ(code(0.0031308f), 10u);
    EXPECT_EQ(code(0.0031309f), 10u);
    EXPECT_EQ(code(0.5f / 255.f / 12.92f * 0.999f), 0u);
    EXPECT_EQ(code(0.5f / 255.f / 12.92f * 1.001f), 1u);
    EXPECT_EQ(code(0.0001f), 0u);
    EXPECT_EQ(code(0.9999f), 255u);
    EXPECT_EQ(code(0.99f), 254u);  // 0.99 -> 0.99562 * 255 = 253.88
    EXPECT_EQ(code(0.01f), 25u);   // 0.0998987 * 255 = 25.47

    // Every code boundary, exactly: the largest float below it and the boundary itself, against double math.
    for (int k = 1; k <= 255; ++k) {
        // The boundary of code k in linear terms, from the inverse OETF.
        const double s = (k - 0.5) / 255.0;
        const double lin = s <= 0.04045 ? s / 12.92 : std::pow((s + 0.055) / 1.055, 2.4);
        float v = std::nextafter(float(lin), 0.f);
        for (int i = 0; i < 4; ++i, v = std::nextafter(v, 2.f))
            ASSERT_EQ(int(code(v)), srgbCode(double(v))) << "near code " << k << ": " << v;
    }
    // A dense sample of [0, 1]: every 97th float.
    for (uint32_t bits = 0; bits <= 0x3F800000u; bits += 97) {
        const float v = bitsToFloat(bits);
        ASSERT_EQ(int(code(v)), srgbCode(double(v))) << v;
    }
}

// ---------------------------------------------------------------------------------------------------------------
// Bad input, optional output, determinism, reflection

TEST(ToneMap, NonFiniteAndHugeInputsGiveFiniteOutputs) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    const float huge = std::numeric_limits<float>::max();
    const std::vector<glm::vec4> bad = {glm::vec4(nan),
                                        glm::vec4(inf),
                                        glm::vec4(-inf),
                                        glm::vec4(huge),
                                        glm::vec4(-huge),
                                        glm::vec4(nan, inf, -inf, 0.5f),
                                        glm::vec4(1e30f, 1e-30f, 0, 2)};
    for (const char* op : kOperators) {
        for (bool autoExposure : {false, true}) {
            SCOPED_TRACE(std::string(op) + (autoExposure ? " auto" : ""));
            Harness h(nlohmann::json{
                {"operator", op}, {"autoExposure", autoExposure}, {"exposure", 20.f}, {"whitePoint", 1e-3f}});
            h.source->fn = [&](uint64_t, uint32_t x, uint32_t y) { return bad[(y * 16 + x) % bad.size()]; };
            h.run();
            h.run();
            for (uint32_t y = 0; y < 16; ++y)
                for (uint32_t x = 0; x < 16; ++x) {
                    const glm::vec4 m = h.mapped(x, y);
                    for (int c = 0; c < 4; ++c) ASSERT_TRUE(m[c] >= 0.f && m[c] <= 1.f) << x << "," << y << " " << c;
                }
            // NaN -> black, +Inf -> white, -Inf -> black; alpha clamped (NaN alpha -> 0).
            EXPECT_EQ(h.code(0, 0), glm::uvec4(0u));
            EXPECT_EQ(h.code(1, 0), glm::uvec4(255u));
            EXPECT_EQ(h.code(2, 0), glm::uvec4(0u));
            EXPECT_EQ(h.code(5, 0), glm::uvec4(0u, 255u, 0u, 128u));
            EXPECT_TRUE(std::isfinite(h.stat("exposure")));
        }
    }
}

TEST(ToneMap, DstFloatIsComputedOnlyWhenConsumed) {
    Harness without(nlohmann::json{{"operator", "reinhard"}}, false);
    without.source->fn = sweep(kTestValues);
    without.run();
    EXPECT_EQ(without.graph.fieldTexture("ToneMap.dstFloat"), nullptr);
    const auto& skipped = without.graph.plan().skippedOutputs;
    EXPECT_NE(std::find(skipped.begin(), skipped.end(), "ToneMap.dstFloat"), skipped.end());

    Harness with(nlohmann::json{{"operator", "reinhard"}}, true);
    with.source->fn = sweep(kTestValues);
    with.run();
    // dst is the same with or without dstFloat.
    EXPECT_TRUE(with.field("dst").samePixels(without.field("dst")));
    EXPECT_EQ(with.mapped(6, 0).x, 0.5f);  // 1 / (1 + 1)
}

TEST(ToneMap, IdenticalResultsForAnyThreadCount) {
    std::unique_ptr<Texture> results[2][2];
    double exposure[2];
    for (int run = 0; run < 2; ++run) {
        ThreadLimit limit(run == 0 ? 1 : 2);
        Harness h(nlohmann::json{{"operator", "hable"}, {"autoExposure", true}}, true, 200,
                  136);  // partial tiles at the edges
        h.source->fn = [](uint64_t f, uint32_t x, uint32_t y) {
            const float v = float((x * 7919u + y * 104729u + f * 31u) % 1000u) * 0.013f;
            return glm::vec4(v, 0.5f * v, 2.f * v, 1.f);
        };
        for (int f = 0; f < 3; ++f) h.run();
        exposure[run] = h.stat("exposure");
        for (int i = 0; i < 2; ++i) {
            const Texture& t = h.field(i == 0 ? "dst" : "dstFloat");
            results[run][i] = std::make_unique<Texture>(t.width(), t.height(), t.format());
            results[run][i]->copyFrom(t);
        }
    }
    EXPECT_EQ(exposure[0], exposure[1]);
    EXPECT_TRUE(results[0][0]->samePixels(*results[1][0]));
    EXPECT_TRUE(results[0][1]->samePixels(*results[1][1]));
}

TEST(ToneMap, VectorPathEqualsTheReferenceKernel) {
    const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
    const ImageFn input = [&](uint64_t, uint32_t x, uint32_t y) {
        const uint32_t h = (x * 2654435761u) ^ (y * 40503u);
        // Rows of black (a sky: zero, denormal, below the first code, negative) and of white or mixed runs, so whole
        // vectors take the encoding's shortcut for code 0 and 255 and others mix it with the table.
        const float black[4] = {0.f, 1e-40f, 1e-6f, -2.f};
        if (y % 6 == 0) return glm::vec4(black[x % 4], black[(x + 1) % 4], black[(x + 2) % 4], 1.f);
        if (y % 6 == 1) return x % 16 < 8 ? glm::vec4(1e30f, 1e30f, 1e30f, 1.f) : glm::vec4(0.f, 0.f, 0.f, 1.f);
        if (h % 53u == 0) return glm::vec4(nan, 1.f, inf, -inf);
        const float v = float(h % 100000u) * 1e-3f * (h % 7u == 0 ? 1e-4f : 1.f);
        return glm::vec4(v, 0.37f * v, v * v, float(h % 300u) / 256.f - 0.1f);
    };
    for (const char* op : kOperators) {
        for (bool autoExposure : {false, true}) {
            SCOPED_TRACE(std::string(op) + (autoExposure ? " auto" : ""));
            std::unique_ptr<Texture> results[2][2];
            double measured[2];
            for (int reference = 0; reference < 2; ++reference) {
                Harness h(nlohmann::json{{"operator", op},
                                         {"exposure", 0.7f},
                                         {"autoExposure", autoExposure},
                                         {"reference", reference == 1}},
                          true, 291, 41);  // rows of two 128-pixel chunks and a rest not a multiple of the vector
                h.source->fn = input;
                h.run();
                measured[reference] = h.stat("measuredLuminance");
                for (int i = 0; i < 2; ++i) results[reference][i] = copyOf(h.field(i == 0 ? "dst" : "dstFloat"));
            }
            // The log-average sums in a different order (vector lanes); the mapping itself is bit-identical.
            EXPECT_NEAR(measured[0], measured[1], 1e-6 * std::max(1.0, measured[1]));
            if (!autoExposure) {
                EXPECT_TRUE(results[0][0]->samePixels(*results[1][0]));
                EXPECT_TRUE(results[0][1]->samePixels(*results[1][1]));
            }
        }
    }
}

TEST(ToneMap, ReflectionDoesNotDependOnParameters) {
    auto fieldsWith = [](const nlohmann::json& params) { return test::reflectedFields(registry(), "ToneMap", params); };
    const auto reference = fieldsWith(nlohmann::json::object());
    EXPECT_EQ(fieldsWith({{"operator", "hable"}, {"autoExposure", true}, {"exposure", -3.f}}), reference);
    EXPECT_EQ(fieldsWith({{"operator", "linear"}, {"key", 0.5f}, {"whitePoint", 9.f}}), reference);
}
