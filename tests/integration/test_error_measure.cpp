// ErrorMeasure: closed-form metric values (identical images, constant offset, temporal change), running means
// after warm-up, the optional error output only planned when consumed, metric-name validation, pass-through of
// src, determinism across thread counts.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <functional>
#include <glm/glm.hpp>
#include <limits>
#include <map>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/Error.h"
#include "loom/Graph.h"
#include "loom/Metrics.h"
#include "loom/Parallel.h"
#include "loom/RenderGraph.h"
#include "loom/Texture.h"

using namespace loom;

namespace {

using Fn = std::function<glm::vec4(uint64_t frame, uint32_t x, uint32_t y)>;

constexpr uint32_t kSize = 64;

/// Src and Ref (FunctionSource) -> ErrorMeasure ("Measure"), run one frame at a time.
struct Harness {
    explicit Harness(const nlohmann::json& params = nlohmann::json::object(),
                     std::vector<std::string> outputs = {"Measure.dst"})
        : graph(describe(params, outputs), test::registryWithFunctionSource()) {
        CompileOptions options;
        options.width = kSize;
        options.height = kSize;
        graph.compile(options);
        src = dynamic_cast<test::FunctionSource*>(graph.pass("Src"));
        ref = dynamic_cast<test::FunctionSource*>(graph.pass("Ref"));
    }

    static GraphDesc describe(const nlohmann::json& params, const std::vector<std::string>& outputs) {
        nlohmann::json g = {
            {"loom_graph", 1},
            {"name", "errormeasure"},
            {"passes",
             {{{"name", "Src"}, {"type", "FunctionSource"}},
              {{"name", "Ref"}, {"type", "FunctionSource"}},
              {{"name", "Measure"}, {"type", "ErrorMeasure"}, {"params", params}}}},
            {"edges", nlohmann::json::array({nlohmann::json::array({"Src.color", "Measure.src"}),
                                             nlohmann::json::array({"Ref.color", "Measure.reference"})})},
            {"outputs", outputs}};
        return parseGraph(g.dump());
    }

    void run() {
        FrameInfo f;
        f.frameIndex = nextFrame++;
        graph.execute(f);
    }
    double stat(const std::string& name) const {
        auto stats = graph.lastStats();
        auto pass = stats.find("Measure");
        if (pass == stats.end()) return std::nan("");
        auto it = pass->second.find(name);
        return it == pass->second.end() ? std::nan("") : it->second;
    }
    bool hasStat(const std::string& name) const { return !std::isnan(stat(name)); }
    const Texture& field(const std::string& name) const {
        const Texture* t = graph.fieldTexture(name);
        if (!t) throw std::runtime_error("no texture for " + name);
        return *t;
    }

    RenderGraph graph;
    test::FunctionSource* src = nullptr;
    test::FunctionSource* ref = nullptr;
    uint64_t nextFrame = 0;
};

using test::hash01;

glm::vec4 image(uint32_t x, uint32_t y) {
    return {hash01(1, x, y), hash01(2, x, y) * 2.f, 0.25f + 0.01f * x, 1.f};
}

bool planHasResource(const RenderGraph& g, const std::string& name) {
    for (const ResourceInfo& r : g.plan().resources)
        if (r.name == name) return true;
    return false;
}

}  // namespace

TEST(ErrorMeasure, IdenticalImagesGiveZeroErrorAndPassSrcThrough) {
    Harness h(nlohmann::json::object(), {"Measure.dst", "Measure.error"});
    h.src->fn = [](uint64_t, uint32_t x, uint32_t y) { return image(x, y); };
    h.ref->fn = h.src->fn;
    h.run();
    EXPECT_EQ(h.stat("relMSE"), 0.0);
    EXPECT_EQ(h.stat("smape"), 0.0);
    EXPECT_EQ(h.stat("ssim"), 1.0);
    EXPECT_EQ(h.stat("flip"), 0.0);
    EXPECT_EQ(h.stat("psnr"), kPsnrCap);
    EXPECT_EQ(h.stat("nonFinite"), 0.0);
    EXPECT_FALSE(h.hasStat("temporal")) << "no temporal error on the first frame (history invalid)";
    EXPECT_TRUE(test::sameBits(h.field("Measure.dst"), h.field("Src.color")));
    const auto err = h.field("Measure.error").view<float>();
    for (uint32_t y = 0; y < kSize; ++y)
        for (uint32_t x = 0; x < kSize; ++x) ASSERT_EQ(err.at(x, y), 0.f) << x << ", " << y;
}

TEST(ErrorMeasure, ConstantOffsetGivesClosedFormRelMse) {
    // ref = c, src = c + d on R, G, B: relMSE = d^2 / (c^2 + eps) exactly (dyadic values, no rounding in x - y).
    const float c = 0.5f, d = 0.25f;
    Harness h(nlohmann::json{{"metrics", "relMSE, smape"}, {"errorImage", "relMSE"}}, {"Measure.dst", "Measure.error"});
    h.ref->fn = [&](uint64_t, uint32_t, uint32_t) { return glm::vec4(c, c, c, 1.f); };
    h.src->fn = [&](uint64_t, uint32_t, uint32_t) { return glm::vec4(c + d, c + d, c + d, 0.f); };
    h.run();
    const double want = double(d) * d / (double(c) * c + kRelMseEpsilon);
    EXPECT_NEAR(h.stat("relMSE"), want, 1e-12);
    EXPECT_NEAR(h.stat("smape"), double(d) / (2.0 * c + d + kSmapeEpsilon), 1e-12);
    EXPECT_FALSE(h.hasStat("psnr")) << "only the listed metrics are reported";
    EXPECT_NEAR(h.field("Measure.error").view<float>().at(17, 33), want, 1e-6);
}

TEST(ErrorMeasure, RunningMeansExcludeWarmupFrames) {
    const int warmup = 3, frames = 9;
    Harness h(nlohmann::json{{"warmupFrames", warmup}});
    h.ref->fn = [](uint64_t, uint32_t x, uint32_t y) { return image(x, y); };
    h.src->fn = [](uint64_t f, uint32_t x, uint32_t y) {
        return image(x, y) + glm::vec4(0.05f * float(f + 1) * hash01(f + 7, x, y));
    };
    const char* const metrics[] = {"relMSE", "smape", "psnr", "ssim", "flip", "temporal"};
    std::map<std::string, double> sums;
    std::map<std::string, int> counts;
    for (int f = 0; f < frames; ++f) {
        h.run();
        for (const char* m : metrics) {
            if (f < warmup) {
                EXPECT_FALSE(h.hasStat(std::string("mean.") + m)) << m << " frame " << f;
            }
            if (!h.hasStat(m)) continue;
            if (f >= warmup) {
                sums[m] += h.stat(m);
                ++counts[m];
            }
        }
    }
    for (const char* m : metrics) {
        SCOPED_TRACE(m);
        ASSERT_EQ(counts[m], frames - warmup);
        EXPECT_NEAR(h.stat(std::string("mean.") + m), sums[m] / counts[m], 1e-12 * std::abs(sums[m]) + 1e-15);
    }
    EXPECT_EQ(h.stat("meanFrames"), frames - warmup);
    // A history reset restarts the means: the warm-up applies again.
    h.graph.resetHistory();
    h.run();
    EXPECT_FALSE(h.hasStat("mean.relMSE"));
}

TEST(ErrorMeasure, ErrorOutputIsOnlyPlannedWhenConsumed) {
    {
        Harness h;
        EXPECT_FALSE(planHasResource(h.graph, "Measure.error"));
        EXPECT_EQ(h.graph.fieldTexture("Measure.error"), nullptr);
        h.src->fn = [](uint64_t, uint32_t x, uint32_t y) { return image(x, y); };
        h.run();  // runs without the output
        EXPECT_TRUE(h.hasStat("flip"));
    }
    {
        Harness h(nlohmann::json::object(), {"Measure.dst", "Measure.error"});
        EXPECT_TRUE(planHasResource(h.graph, "Measure.error"));
    }
}

TEST(ErrorMeasure, UnknownMetricNameIsBadInputWithSuggestion) {
    Error e = test::expectError([] { Harness h(nlohmann::json{{"metrics", "relMSE,ssmi"}}); });
    EXPECT_EQ(e.kind(), ErrorKind::BadInput);
    const std::string text = e.what();
    EXPECT_NE(text.find("metrics"), std::string::npos) << text;
    EXPECT_NE(text.find("ssmi"), std::string::npos) << text;
    EXPECT_NE(e.info().suggestion.find("ssim"), std::string::npos) << text;

    // Set between frames: the next frame reports it.
    Harness h;
    h.graph.setParam("Measure", "metrics", "psnr,flp", "test");
    Error e2 = test::expectError([&] { h.run(); });
    EXPECT_NE(e2.info().suggestion.find("flip"), std::string::npos) << e2.what();
}

TEST(ErrorMeasure, TemporalErrorClosedForms) {
    {
        // A static identical pair: no temporal error.
        Harness h;
        h.src->fn = [](uint64_t, uint32_t x, uint32_t y) { return image(x, y); };
        h.ref->fn = h.src->fn;
        for (int f = 0; f < 3; ++f) h.run();
        EXPECT_EQ(h.stat("temporal"), 0.0);
    }
    {
        // A static reference and a src that grows by d per frame on R, G, B: |(x_t - x_{t-1}) - 0| = d.
        const float d = 0.125f;
        Harness h(nlohmann::json{{"metrics", ""}});
        h.ref->fn = [](uint64_t, uint32_t x, uint32_t y) { return image(x, y); };
        h.src->fn = [&](uint64_t f, uint32_t, uint32_t) { return glm::vec4(d * float(f)); };
        h.run();
        EXPECT_FALSE(h.hasStat("temporal"));
        for (int f = 1; f < 4; ++f) {
            h.run();
            EXPECT_NEAR(h.stat("temporal"), d, 1e-12) << "frame " << f;
        }
        // The history fields hold last frame's images.
        EXPECT_TRUE(test::sameBits(h.field("Measure.prevSrc"), h.field("Src.color")));
    }
}

TEST(ErrorMeasure, DeterministicForOneAndTwoThreads) {
    auto runWith = [](unsigned threads, std::map<std::string, double>& stats, std::vector<float>& error) {
        ThreadLimit limit(threads);
        Harness h(nlohmann::json{{"warmupFrames", 1}, {"errorImage", "ssim"}}, {"Measure.dst", "Measure.error"});
        h.ref->fn = [](uint64_t, uint32_t x, uint32_t y) { return image(x, y); };
        h.src->fn = [](uint64_t f, uint32_t x, uint32_t y) { return image(x, y) * (0.9f + 0.1f * hash01(f, x, y)); };
        for (int f = 0; f < 4; ++f) h.run();
        stats = h.graph.lastStats().at("Measure");
        const auto e = h.field("Measure.error").view<float>();
        for (uint32_t y = 0; y < kSize; ++y)
            for (uint32_t x = 0; x < kSize; ++x) error.push_back(e.at(x, y));
    };
    std::map<std::string, double> s1, s2;
    std::vector<float> e1, e2;
    runWith(1, s1, e1);
    runWith(2, s2, e2);
    ASSERT_FALSE(s1.empty());
    EXPECT_EQ(s1, s2);
    ASSERT_EQ(e1.size(), e2.size());
    EXPECT_EQ(std::memcmp(e1.data(), e2.data(), e1.size() * sizeof(float)), 0);
}

TEST(ErrorMeasure, NonFiniteInputIsCountedAndNeverReachesTheStatsTheErrorImageOrDst) {
    for (const char* metric : {"relMSE", "smape", "psnr", "ssim", "flip"}) {
        SCOPED_TRACE(metric);
        Harness h(nlohmann::json{{"errorImage", metric}, {"warmupFrames", 0}}, {"Measure.dst", "Measure.error"});
        h.ref->fn = [](uint64_t, uint32_t x, uint32_t y) { return image(x, y); };
        h.src->fn = [](uint64_t, uint32_t x, uint32_t y) {
            if (x == 5 && y == 9) return glm::vec4(std::nanf(""), 0.f, 0.f, 1.f);
            if (x == 40 && y == 2) return glm::vec4(0.f, INFINITY, 0.f, 1.f);
            return image(x, y);
        };
        h.run();
        h.run();
        EXPECT_EQ(h.stat("nonFinite"), 2.0);
        const auto stats = h.graph.lastStats();
        for (const auto& [name, value] : stats.at("Measure")) EXPECT_TRUE(std::isfinite(value)) << name;
        const auto err = h.field("Measure.error").view<float>();
        for (uint32_t y = 0; y < kSize; ++y)
            for (uint32_t x = 0; x < kSize; ++x) ASSERT_TRUE(std::isfinite(err.at(x, y))) << x << ", " << y;
        // dst is src with the non-finite channels set to 0.
        const auto dst = h.field("Measure.dst").view<glm::vec4>();
        EXPECT_EQ(dst.at(5, 9), glm::vec4(0.f, 0.f, 0.f, 1.f));
        EXPECT_EQ(dst.at(40, 2), glm::vec4(0.f, 0.f, 0.f, 1.f));
        EXPECT_EQ(dst.at(6, 9), image(6, 9));
    }
}

TEST(ErrorMeasure, DisabledPassesSrcThroughAndReportsNothing) {
    Harness h(nlohmann::json{{"enabled", false}}, {"Measure.dst", "Measure.error"});
    h.ref->fn = [](uint64_t, uint32_t x, uint32_t y) { return image(x, y); };
    h.src->fn = [](uint64_t f, uint32_t x, uint32_t y) { return image(x, y) * float(f + 2); };
    h.run();
    h.run();
    EXPECT_FALSE(h.hasStat("flip"));
    EXPECT_FALSE(h.hasStat("temporal"));
    EXPECT_TRUE(test::sameBits(h.field("Measure.dst"), h.field("Src.color")));
    // Enabled again: history was kept, so the temporal error is there at once.
    h.graph.setParam("Measure", "enabled", true, "test");
    h.run();
    EXPECT_TRUE(h.hasStat("temporal"));
    EXPECT_GT(h.stat("flip"), 0.0);
}

namespace {

/// Src and Ref (FunctionSource, on the CPU) into Measure on `device`, every field observed.
std::unique_ptr<RenderGraph> measureOn(const std::string& device, const nlohmann::json& params,
                                       const std::vector<std::string>& outputs) {
    auto graph = std::make_unique<RenderGraph>(Harness::describe(params, outputs), test::registryWithFunctionSource());
    CompileOptions options;
    options.width = 45;
    options.height = 29;
    options.device = device;
    options.observe = {"Measure.*"};
    graph->compile(options);
    // Noise that grows with the frame, NaN and Inf here and there (in src and in the reference).
    dynamic_cast<test::FunctionSource*>(graph->pass("Src"))->fn = [](uint64_t f, uint32_t x, uint32_t y) {
        glm::vec4 c = 2.f * image(x, y) + glm::vec4(0.1f * float(f + 1) * hash01(f + 7, x, y));
        if ((x + 5 * y + f) % 41 == 0) c.y = std::numeric_limits<float>::infinity();
        if ((3 * x + y) % 53 == 0) c.w = std::numeric_limits<float>::quiet_NaN();
        return c;
    };
    dynamic_cast<test::FunctionSource*>(graph->pass("Ref"))->fn = [](uint64_t f, uint32_t x, uint32_t y) {
        glm::vec4 c = 2.f * image(x, y);
        if (f == 1 && x == 7 && y == 3) c.x = std::numeric_limits<float>::quiet_NaN();
        return c;
    };
    return graph;
}

}  // namespace

// On the emulated device dst, the history, the error image and every stat equal the CPU's bit for bit, at 1 and 2
// threads: RelMSE, SMAPE, PSNR and the temporal error run the CPU's per-pixel functions in the CPU's row order
// (loom/MetricKernels.h); SSIM and FLIP run the CPU's code on host copies. The pass runs on emulated, its own
// fields live there, and the graph copies only its CPU-placed sources in and the observed fields out.
TEST(ErrorMeasure, OnEmulatedEqualsCpuBitForBit) {
    const std::vector<nlohmann::json> cases = {
        nlohmann::json{{"errorImage", "relMSE"}, {"warmupFrames", 1}},
        nlohmann::json{{"errorImage", "smape"}, {"metrics", "relMSE"}},
        nlohmann::json{{"errorImage", "psnr"}, {"metrics", "psnr,smape"}},
        nlohmann::json{{"errorImage", "ssim"}, {"metrics", "ssim,flip"}},
        nlohmann::json{{"errorImage", "flip"}},
        nlohmann::json{{"errorImage", "flip"}, {"metrics", ""}, {"enabled", false}},
    };
    for (const nlohmann::json& params : cases) {
        for (unsigned threads : {1u, 2u}) {
            SCOPED_TRACE(params.dump() + " threads " + std::to_string(threads));
            ThreadLimit limit(threads);
            auto cpu = measureOn("cpu", params, {"Measure.dst", "Measure.error"});
            auto emulated = measureOn("emulated", params, {"Measure.dst", "Measure.error"});
            for (const PlacedPass& p : emulated->plan().placement)
                EXPECT_EQ(p.device, p.name == "Measure" ? DeviceKind::Emulated : DeviceKind::Cpu) << p.name;
            for (const TransferInfo& t : emulated->plan().transfers) {
                if (!t.after) EXPECT_EQ(t.reason, "for Measure") << t.field;
            }
            for (uint64_t f = 0; f < 4; ++f) {
                const FrameInfo frame{f, f / 30.0, nullptr, nullptr};
                cpu->execute(frame);
                emulated->execute(frame);
                const size_t fields = test::expectSameFields(*cpu, *emulated, "Measure.", "frame " + std::to_string(f));
                EXPECT_GE(fields, 4u) << "dst, error and the two history fields";
                EXPECT_EQ(cpu->lastStats(), emulated->lastStats()) << "frame " << f;
            }
        }
    }
}
