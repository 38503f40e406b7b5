// SVGFPass on the emulated device (every stage a launch2D over the scalar kernels, its fields in device memory)
// against the CPU, frame after frame on synthetic input with a sub-pixel pan, a moving box that disoccludes what it
// leaves, sky, emission, a non-finite sample and a lighting step seen by the temporal gradients:
// - against the CPU's own reference stages (referenceStages, referenceAtrous: the same scalar kernels), every field
//   of the pass, scratch included, bit for bit, but for the à-trous levels, which the CPU's build contracts into
//   FMAs (kContractionTolerance);
// - against the CPU's default fast path (the Highway twins), the history, moments, length, guides, variance estimate
//   and debug outputs bit for bit (the fused temporal and variance stages reproduce the scalar kernels exactly), and
//   the filtered output within the fast à-trous' stated tolerance (see kAtrousTolerance);
// - the same bits at 1 and 2 threads;
// - graphs/PathTracerSVGF.json on the animated Cornell box, whose other passes fall back to the CPU.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdio>
#include <fstream>
#include <functional>
#include <glm/glm.hpp>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "../apps/loom/SceneSetup.h"
#include "TestUtil.h"
#include "loom/Parallel.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

constexpr uint32_t kW = 48, kH = 40;
constexpr int kFrames = 6;

/// The fast à-trous against the reference kernel: 3e-5 relative, values below 1e-3 counting as 1e-3 (AtrousSimd.h,
/// passes/SVGF/tests/test_atrous.cpp: each weight within ~6e-6, a level's ratio about twice that, summed over the
/// levels); the fused remodulation adds rounding (3e-7, tests/integration/test_svgf.cpp). With a feedback tap the
/// difference also enters the history and is carried from frame to frame: kFeedbackTolerance over kFrames frames.
constexpr double kAtrousTolerance = 3e-5;
constexpr double kFeedbackTolerance = 1e-4;
/// The CPU's reference à-trous (Atrous.cpp) is compiled with GCC's default contraction of a * b + c into FMAs
/// (x86-64-v3); the device stages without it (on the GPU too, --fmad=false), as the temporal and variance kernels
/// everywhere. The levels' results differ by that rounding (measured <= 1.4e-6 relative over these frames), all else
/// is the same bits.
constexpr double kContractionTolerance = 1e-5;

/// Which optional inputs the source offers.
struct Inputs {
    bool split = false, gradient = false, specular = false;
};

/// Every SVGF input, from a function of frame and pixel (below), on the CPU.
class DeviceTestSource final : public RenderPass {
public:
    explicit DeviceTestSource(Inputs in) : mIn(in) {}
    void reflect(Reflection& r, const CompileInfo&) const override {
        for (const char* c : {"color", "albedo", "emission", "normW"}) r.output(c, Format::RGBA32F);
        for (const char* c : {"linearZ", "mvec"}) r.output(c, Format::RG32F);
        r.output("meshId", Format::R32U);
        if (mIn.split) {
            r.output("direct", Format::RGBA32F);
            r.output("indirect", Format::RGBA32F);
        }
        if (mIn.gradient) r.output("gradient", Format::RG32F);
        if (mIn.specular) r.output("specAlbedo", Format::RGBA32F);
    }
    void execute(PassContext& ctx) override;

private:
    Inputs mIn;
};

float hash01(uint64_t frame, uint32_t x, uint32_t y, uint32_t salt = 0) {
    return test::hash01(frame + (uint64_t(salt) << 40), x, y);
}

/// The left half's light: a step down at frame 3 (what the temporal gradients see).
float light(uint64_t frame, float u) {
    return u < kW / 2 && frame >= 3 ? 0.4f : 1.f;
}

void DeviceTestSource::execute(PassContext& ctx) {
    const uint64_t frame = ctx.frameIndex();
    auto out4 = [&](const char* name) { return ctx.output(name)->view<glm::vec4>(); };
    auto out2 = [&](const char* name) { return ctx.output(name)->view<glm::vec2>(); };
    const auto meshId = ctx.output("meshId")->view<uint32_t>();
    for (uint32_t y = 0; y < kH; ++y)
        for (uint32_t x = 0; x < kW; ++x) {
            // Scene coordinates: the view pans 0.37 px a frame; a box moves 3 px a frame over two planes.
            const float pan = 0.37f * float(frame), u = float(x) + pan;
            const float box = 8.f + 3.f * float(frame);
            const bool inBox = u >= box && u < box + 10.f && y >= 10 && y < 22;
            glm::vec2 z = u < kW / 2 ? glm::vec2(4.f, 0.02f) : glm::vec2(6.f, 0.03f);
            glm::vec3 n = u < kW / 2 ? glm::vec3(0.f, 0.f, 1.f) : glm::normalize(glm::vec3(0.3f, 0.f, 0.95f));
            uint32_t mesh = u < kW / 2 ? 0 : 1;
            glm::vec2 mvec(-0.37f / kW, 0.f);
            if (inBox) {
                z = glm::vec2(2.f, 0.01f);
                n = glm::normalize(glm::vec3(0.f, 0.2f, 0.98f));
                mesh = 2;
                mvec.x = -3.37f / kW;
            }
            if (y < 3) {  // sky
                z = glm::vec2(-1.f, 0.f);
                mesh = ~0u;
            }
            const glm::vec3 albedo = ((int(u) / 4 + y / 4) % 2) ? glm::vec3(0.8f, 0.6f, 0.4f) : glm::vec3(0.3f, 0.5f, 0.7f);
            const glm::vec3 emission(x % 7 == 0 && y % 4 == 1 ? 0.3f : 0.f, 0.f, 0.f);
            const float noise = hash01(frame, x, y), noise1 = hash01(frame, x, y, 1);
            const float l = light(frame, u);
            glm::vec3 direct = albedo * l * (0.2f + 1.6f * noise * noise) + emission;
            const glm::vec3 indirect = albedo * (0.05f + 0.9f * noise1 * noise1 * noise1);
            glm::vec3 color = mIn.split ? direct + indirect : direct;
            if (frame == 3 && x == 30 && y == 20) color.r = direct.r = NAN;
            out4("color").at(x, y) = glm::vec4(color, 1.f);
            out4("albedo").at(x, y) = glm::vec4(albedo, 1.f);
            out4("emission").at(x, y) = glm::vec4(emission, 0.f);
            out4("normW").at(x, y) = glm::vec4(n, 0.f);
            out2("linearZ").at(x, y) = z;
            out2("mvec").at(x, y) = mvec;
            meshId.at(x, y) = mesh;
            if (mIn.split) {
                out4("direct").at(x, y) = glm::vec4(direct, 1.f);
                out4("indirect").at(x, y) = glm::vec4(indirect, 1.f);
            }
            if (mIn.gradient) {
                // Last frame's sample of each 3x3 block re-shaded now: the same noise, this frame's light.
                const float m = 0.5f + hash01(frame + 7, x - x % 3, y - y % 3);
                out2("gradient").at(x, y) =
                    frame > 0 ? glm::vec2(light(frame, u) * m, light(frame - 1, u) * m) : glm::vec2(0.f);
            }
            if (mIn.specular) out4("specAlbedo").at(x, y) = glm::vec4(glm::vec3(inBox ? 0.5f : 0.04f), 0.f);
        }
}

const char* sourceType(Inputs in) {
    static const char* names[8] = {"SvgfDevSrc0", "SvgfDevSrc1", "SvgfDevSrc2", "SvgfDevSrc3",
                                   "SvgfDevSrc4", "SvgfDevSrc5", "SvgfDevSrc6", "SvgfDevSrc7"};
    return names[(in.split ? 1 : 0) | (in.gradient ? 2 : 0) | (in.specular ? 4 : 0)];
}

PluginRegistry& registry() {
    static PluginRegistry r({LOOM_TEST_PLUGIN_DIR}, false);
    static const bool registered = [] {
        for (int k = 0; k < 8; ++k) {
            const Inputs in{(k & 1) != 0, (k & 2) != 0, (k & 4) != 0};
            r.registerPass(sourceType(in), "synthetic SVGF inputs", [in] { return std::make_unique<DeviceTestSource>(in); });
        }
        return true;
    }();
    (void)registered;
    return r;
}

/// Source -> SVGF with `params`, SVGF placed on `device`, every field observed (readable after each frame), and
/// transients poisoned with NaN (a read before a write shows).
std::unique_ptr<RenderGraph> svgfGraph(Inputs in, const nlohmann::json& params, const std::string& device) {
    const nlohmann::json g = {{"loom_graph", 1},
                              {"name", "svgf_devices"},
                              {"passes",
                               {{{"name", "Source"}, {"type", sourceType(in)}, {"device", "cpu"}},
                                {{"name", "SVGF"}, {"type", "SVGFPass"}, {"params", params}}}},
                              {"outputs", {"SVGF.filtered", "SVGF.variance", "SVGF.historyLength"}}};
    auto graph = std::make_unique<RenderGraph>(parseGraph(g.dump()), registry());
    CompileOptions o;
    o.width = kW;
    o.height = kH;
    o.device = device;
    o.observe = {"*"};
    o.poisonTransients = true;
    graph->compile(o);
    return graph;
}

DeviceKind placement(const RenderGraph& g, const std::string& pass) {
    for (const PlacedPass& p : g.plan().placement)
        if (p.name == pass) return p.device;
    ADD_FAILURE() << pass << " not placed";
    return DeviceKind::Cpu;
}

/// The SVGF fields of a compiled graph (outputs, history, scratch).
std::vector<std::string> svgfFields(const RenderGraph& g) {
    std::vector<std::string> out;
    for (const auto& r : g.plan().resources)
        if (r.name.rfind("SVGF.", 0) == 0 && r.name.find(' ') == std::string::npos) out.push_back(r.name);
    return out;
}

/// Largest |a - b| / (|b| + 1e-3) over every channel of every pixel (NaN or infinite: infinity).
double maxRelativeError(const Texture& a, const Texture& b) {
    double worst = 0.0;
    const uint32_t channels = formatInfo(a.format()).channels;
    for (uint32_t y = 0; y < a.height(); ++y)
        for (uint32_t x = 0; x < a.width(); ++x)
            for (uint32_t c = 0; c < channels; ++c) {
                const double va = a.texel(x, y, c), vb = b.texel(x, y, c);
                const double e = std::abs(va - vb) / (std::abs(vb) + 1e-3);
                worst = std::max(worst, std::isfinite(e) ? e : INFINITY);
            }
    return worst;
}

void runFrame(RenderGraph& g, uint64_t frame) {
    g.execute(FrameInfo{frame, double(frame) / 30.0, nullptr, nullptr});
}

/// How an emulated field compares with the CPU's: bit for bit, within a tolerance, or not at all.
struct Expectation {
    double tolerance = 0.0;  ///< 0: bit for bit
    bool compared = true;
};

/// Runs the CPU graph (`cpuParams`) and the emulated one (`params`) side by side for kFrames frames and compares each
/// SVGF field after each frame as `expect(field)` says, and the rejected-sample counts.
void compareWithCpu(Inputs in, const nlohmann::json& params, const nlohmann::json& cpuParams,
                    const std::function<Expectation(const std::string&)>& expect, const std::string& what) {
    auto cpu = svgfGraph(in, cpuParams, "cpu");
    auto emulated = svgfGraph(in, params, "emulated");
    ASSERT_EQ(placement(*emulated, "SVGF"), DeviceKind::Emulated) << what;
    ASSERT_EQ(placement(*emulated, "Source"), DeviceKind::Cpu) << what;
    const std::vector<std::string> fields = svgfFields(*cpu);
    double worst = 0.0;
    ASSERT_EQ(fields, svgfFields(*emulated)) << what;
    for (uint64_t f = 0; f < kFrames; ++f) {
        runFrame(*cpu, f);
        runFrame(*emulated, f);
        EXPECT_EQ(cpu->lastStats().at("SVGF").at("nonFinite"), emulated->lastStats().at("SVGF").at("nonFinite"))
            << what << " frame " << f;
        for (const std::string& field : fields) {
            const Expectation e = expect(field);
            if (!e.compared) continue;
            const Texture* a = cpu->fieldTexture(field);
            const Texture* b = emulated->fieldTexture(field);
            ASSERT_TRUE(a && b) << field;
            ASSERT_TRUE(b->onHost()) << field;
            if (e.tolerance == 0.0)
                EXPECT_TRUE(test::sameBits(*b, *a)) << what << " " << field << " frame " << f;
            else {
                const double error = maxRelativeError(*b, *a);
                worst = std::max(worst, error);
                EXPECT_LE(error, e.tolerance) << what << " " << field << " frame " << f;
            }
        }
    }
    if (worst > 0.0) std::printf("%s: largest relative difference %.3g\n", what.c_str(), worst);
}

const Inputs kVariants[] = {{false, false, false}, {true, false, false}, {false, true, true}, {true, true, true}};

std::string describe(Inputs in, const nlohmann::json& params) {
    return std::string(in.split ? "split " : "") + (in.gradient ? "gradient " : "") + (in.specular ? "specular " : "") +
           params.dump();
}

}  // namespace

// The pass says where its kernels run: the CPU and the emulated device always (cuda where nvcc compiled them).
TEST(SvgfDevices, RunsOnCpuAndEmulated) {
    auto pass = registry().create("SVGFPass");
    EXPECT_TRUE(pass->runsOn(DeviceKind::Cpu));
    EXPECT_TRUE(pass->runsOn(DeviceKind::Emulated));
}

// Emulated against the CPU's reference stages, the same scalar kernels one stage after the other: every SVGF field,
// scratch included, bit for bit but for the à-trous levels' rounding (kContractionTolerance), for the combined signal and the split, with and without gradients and specAlbedo,
// and for the parameters that take other branches (no temporal, a feedback tap, the low-variance tile skip, no
// levels, disabled).
TEST(SvgfDevices, EmulatedEqualsTheReferenceStagesBitForBit) {
    const nlohmann::json paramSets[] = {nlohmann::json::object(),
                                        {{"temporal", false}},
                                        {{"feedbackTap", 1}, {"iterations", 3}},
                                        {{"skipRelVariance", 0.05}},
                                        {{"iterations", 0}},
                                        {{"enabled", false}}};
    for (const Inputs& in : kVariants)
        for (const nlohmann::json& params : paramSets) {
            nlohmann::json reference = params;
            reference["referenceStages"] = true;
            reference["referenceAtrous"] = true;
            const bool feedback = params.contains("feedbackTap"), disabled = params.contains("enabled");
            compareWithCpu(
                in, params, reference,
                [&](const std::string& field) {
                    // Disabled, the pass writes no scratch (it stays NaN-poisoned on both).
                    for (const char* scratch : {"SVGF.integrated", "SVGF.integratedIndirect", "SVGF.estimate",
                                                "SVGF.estimateIndirect", "SVGF.shadingChange"})
                        if (disabled && field == scratch) return Expectation{0.0, false};
                    for (const char* levels : {"SVGF.filtered", "SVGF.integrated", "SVGF.integratedIndirect"})
                        if (field == levels) return Expectation{kContractionTolerance};
                    if (feedback)
                        for (const char* fed : {"SVGF.illumination", "SVGF.illuminationIndirect", "SVGF.estimate",
                                                "SVGF.estimateIndirect", "SVGF.variance"})
                            if (field == fed) return Expectation{kContractionTolerance};
                    // Without gradients the history clamp scales the moments by the fed-back history's luminance.
                    if (feedback && !in.gradient && field.rfind("SVGF.moments", 0) == 0)
                        return Expectation{kContractionTolerance};
                    return Expectation{};
                },
                describe(in, params));
        }
}

// Emulated against the CPU's default fast path (Highway twins). The fused temporal and variance stages perform the
// scalar kernels' operations in their order, so the history (with feedbackTap -1 the unfiltered signal), moments,
// length, last frame's guides, the variance estimate and the debug outputs are the same bits; the filtered output
// comes from the fast à-trous: within its tolerance. The integrated scratch is not compared: after the frame the
// fast path leaves the temporal result there (the levels run in packed planes), the reference path the filtered
// signal.
TEST(SvgfDevices, EmulatedMatchesTheCpuFastPath) {
    const auto expect = [](const std::string& field) {
        if (field == "SVGF.filtered") return Expectation{kAtrousTolerance};
        if (field.rfind("SVGF.integrated", 0) == 0) return Expectation{0.0, false};
        return Expectation{};
    };
    for (const Inputs& in : kVariants) {
        compareWithCpu(in, nlohmann::json::object(), nlohmann::json::object(), expect, describe(in, nlohmann::json::object()));
        compareWithCpu(in, {{"temporal", false}}, {{"temporal", false}}, expect, describe(in, {{"temporal", false}}));
    }
    // With a feedback tap the history is a fast à-trous level: it and what is computed from it (the estimate, the
    // variance, the output) within the tolerance carried over the frames; length and guides do not depend on it,
    // nor do the moments where gradients are connected (without them the history clamp scales the moments by the
    // history's luminance).
    const nlohmann::json tap = {{"feedbackTap", 0}};
    for (const Inputs& in : {kVariants[0], kVariants[3]}) {
        const auto expectFeedback = [&](const std::string& field) {
            for (const char* exact : {"SVGF.moments", "SVGF.momentsIndirect", "SVGF.length", "SVGF.historyLength",
                                      "SVGF.prevLinearZ", "SVGF.prevNormW", "SVGF.prevMeshId", "SVGF.shadingChange",
                                      "SVGF.clampBox"})
                if (field == exact && (in.gradient || field.rfind("SVGF.moments", 0) != 0)) return Expectation{};
            if (field.rfind("SVGF.integrated", 0) == 0) return Expectation{0.0, false};
            return Expectation{kFeedbackTolerance};
        };
        compareWithCpu(in, tap, tap, expectFeedback, describe(in, tap));
    }
}

// The emulated device gives the same bits at 1 and 2 threads, every field of every frame.
TEST(SvgfDevices, EmulatedIsIdenticalForAnyThreadCount) {
    for (const Inputs& in : {kVariants[1], kVariants[2]}) {
        std::vector<std::vector<Texture>> runs;
        for (unsigned threads : {1u, 2u}) {
            ThreadLimit limit(threads);
            auto g = svgfGraph(in, {{"feedbackTap", 1}}, "emulated");
            std::vector<Texture> fields;
            for (uint64_t f = 0; f < kFrames; ++f) {
                runFrame(*g, f);
                for (const std::string& field : svgfFields(*g)) {
                    const Texture* t = g->fieldTexture(field);
                    Texture copy(t->width(), t->height(), t->format());
                    copy.copyFrom(*t);
                    fields.push_back(std::move(copy));
                }
            }
            runs.push_back(std::move(fields));
        }
        ASSERT_EQ(runs[0].size(), runs[1].size());
        for (size_t i = 0; i < runs[0].size(); ++i) EXPECT_TRUE(test::sameBits(runs[0][i], runs[1][i])) << i;
    }
}

// The shipped path-tracing graph on the animated Cornell box at 64x64, 4 frames: SVGF on the emulated device, the
// G-buffer and the path tracer on the CPU (transfers in between). SVGF's history is the CPU's bit for bit, its
// output within the fast à-trous' tolerance, and the tone-mapped output within one 8-bit step.
TEST(SvgfDevices, PathTracerSvgfGraphOnEmulatedMatchesTheCpu) {
    const uint32_t W = 64, H = 64;
    std::ifstream file(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/PathTracerSVGF.json");
    nlohmann::json desc = nlohmann::json::parse(file);
    // The path tracer stays on the CPU (its device kernels are not its CPU path's bits), so SVGF sees the same input.
    for (auto& pass : desc["passes"])
        if (pass["name"] == "PathTracer") pass["device"] = "cpu";
    auto render = [&](const std::string& device, unsigned threads) {
        ThreadLimit limit(threads);
        auto scene = Scene::load(test::dataScene("cornell_dynamic.gltf"));
        CompileOptions o;
        o.device = device;
        o.observe = {"SVGF.*"};
        auto g = test::compiledGraph(desc, scene, W, H, o);
        if (device == "emulated") EXPECT_EQ(placement(*g, "SVGF"), DeviceKind::Emulated);
        std::vector<std::vector<Texture>> frames;
        for (uint64_t f = 0; f < 4; ++f) {
            const double time = 0.5 + double(f) / 30.0;
            g->execute(cli::sceneFrameAt(scene.get(), f, time, W, H, false));
            std::vector<Texture> out;
            for (const std::string& name : {std::string("ToneMap.dst"), std::string("SVGF.filtered"),
                                            std::string("SVGF.illumination"), std::string("SVGF.moments"),
                                            std::string("SVGF.length")}) {
                const Texture* t = g->fieldTexture(name);
                EXPECT_TRUE(t) << name;
                if (!t) return frames;
                Texture copy(t->width(), t->height(), t->format());
                copy.copyFrom(*t);
                out.push_back(std::move(copy));
            }
            frames.push_back(std::move(out));
        }
        return frames;
    };
    const auto cpu = render("cpu", 2), emulated = render("emulated", 2), emulatedOne = render("emulated", 1);
    ASSERT_EQ(cpu.size(), 4u);
    ASSERT_EQ(emulated.size(), 4u);
    ASSERT_EQ(emulatedOne.size(), 4u);
    for (size_t f = 0; f < cpu.size(); ++f) {
        const Texture& toneCpu = cpu[f][0];
        const Texture& toneEmulated = emulated[f][0];
        double largest = 0.0;
        const uint32_t channels = formatInfo(toneCpu.format()).channels;
        for (uint32_t y = 0; y < H; ++y)
            for (uint32_t x = 0; x < W; ++x)
                for (uint32_t c = 0; c < channels; ++c)
                    largest = std::max(largest, double(std::abs(toneCpu.texel(x, y, c) - toneEmulated.texel(x, y, c))));
        EXPECT_LE(largest, 1.0 / 255.0 + 1e-6) << "ToneMap.dst frame " << f;
        EXPECT_LE(maxRelativeError(emulated[f][1], cpu[f][1]), kAtrousTolerance) << "SVGF.filtered frame " << f;
        for (size_t i = 2; i < cpu[f].size(); ++i)
            EXPECT_TRUE(test::sameBits(emulated[f][i], cpu[f][i])) << "history field " << i << " frame " << f;
        for (size_t i = 0; i < cpu[f].size(); ++i)
            EXPECT_TRUE(test::sameBits(emulated[f][i], emulatedOne[f][i])) << "1 vs 2 threads, field " << i;
    }
}
