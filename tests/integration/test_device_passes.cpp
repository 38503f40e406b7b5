// ToneMap, AccumulatePass and TAAPass on the emulated device (their kernels through launch2D and reduceRows, their
// fields and history in device memory) against the same passes on the CPU, over several frames so the history is
// exercised, at 1 and 2 threads. Bit for bit where the CPU runs the same functor (Accumulate; TAA's reference
// kernel; ToneMap's mapping, whose vector path gives the functor's bits); where it does not, a stated tolerance:
//   - ToneMap with auto exposure: the CPU sums the log-luminance terms in float vector lanes per band of rows, the
//     device in double per row (reduceRows), so the log-average differs in its last bits: the adapted luminance
//     within 1e-5 relative, dstFloat within 1e-5 relative, dst within one 8-bit step;
//   - TAA's tiled vector path against its reference kernel: 1e-4 of max(1, |value|) per channel, the bound its own
//     test (test_taa.cpp) holds after 8 frames of feedback.
// Then the shipped default graphs (PathTracerSVGF, PathTracerSVGFTAA) on cornell_dynamic, emulated against cpu.
#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <string>

#include "TestUtil.h"
#include "loom/Error.h"
#include "loom/Parallel.h"
#include "loom/RenderGraph.h"
#include "loom/Scene.h"

using namespace loom;

namespace {

PluginRegistry& registry() { return test::registryWithFunctionSource(); }

/// TAA's inputs for the tests here: a bright block moving right over noise, with a non-finite pixel now and then.
void setMotionInputs(test::MotionSource& source, uint32_t width, uint32_t height) {
    const auto block = [](uint64_t f, uint32_t x, uint32_t y) { return (x + 3 * f) % 23 < 6 && y % 17 < 9; };
    source.color = [=](uint64_t f, uint32_t x, uint32_t y) {
        const float n = test::hash01(f, x, y);
        glm::vec4 c = block(f, x, y) ? glm::vec4(20.f * n, 15.f, 10.f, 1.f) : glm::vec4(n, 0.5f * n, 0.25f, 1.f);
        if ((x * 7 + y * 3 + f) % 97 == 0) c.x = std::numeric_limits<float>::quiet_NaN();
        return c;
    };
    source.motion = [=](uint64_t f, uint32_t x, uint32_t y) {
        return glm::vec2(block(f, x, y) ? -3.f / float(width) : 0.25f / float(width), 0.1f / float(height));
    };
}

/// A small graph of `json` on `device`, every field observed (so fieldTexture gives each one, history included).
std::unique_ptr<RenderGraph> graphOn(const nlohmann::json& json, const std::string& device, uint32_t w, uint32_t h) {
    auto g = std::make_unique<RenderGraph>(parseGraph(json.dump()), registry());
    CompileOptions o;
    o.width = w;
    o.height = h;
    o.device = device;
    o.observe = {"*"};
    g->compile(o);
    if (auto* motion = dynamic_cast<test::MotionSource*>(g->pass("Src"))) setMotionInputs(*motion, w, h);
    if (auto* src = dynamic_cast<test::FunctionSource*>(g->pass("Src")))
        src->fn = [](uint64_t f, uint32_t x, uint32_t y) {
            const float n = test::hash01(f, x, y);
            glm::vec4 c(4.f * n * n, n, 0.3f + 0.1f * float(f), 1.f);
            if ((x + 5 * y + f) % 41 == 0) c.y = std::numeric_limits<float>::infinity();
            if ((3 * x + y + 2 * f) % 53 == 0) c.z = std::numeric_limits<float>::quiet_NaN();
            if (f == 2 && x < 4) c = glm::vec4(1e30f);  // huge samples: the float sums skip them near the top
            return c;
        };
    return g;
}

std::vector<std::string> fieldsOf(const RenderGraph& g) {
    std::vector<std::string> out;
    for (const auto& r : g.plan().resources)
        if (r.name.find(' ') == std::string::npos) out.push_back(r.name);  // not the transfer copies
    return out;
}

/// Largest |a - b| / max(1, |a|) over float texels (non-finite texels must match as non-finite), or over 8-bit
/// texels the largest difference in steps.
double difference(const Texture& a, const Texture& b) {
    EXPECT_EQ(a.format(), b.format());
    const FormatInfo& info = formatInfo(a.format());
    double worst = 0.0;
    for (uint32_t y = 0; y < a.height(); ++y) {
        const std::byte* ra = a.row(y);
        const std::byte* rb = b.row(y);
        if (info.bytesPerPixel == 4 && (a.format() == Format::RGBA8Srgb || a.format() == Format::RGBA8Unorm)) {
            for (uint32_t i = 0; i < 4 * a.width(); ++i)
                worst = std::max(worst, std::abs(double(uint8_t(ra[i])) - double(uint8_t(rb[i]))));
            continue;
        }
        for (uint32_t i = 0; i < a.width() * info.bytesPerPixel / 4; ++i) {
            float fa, fb;
            std::memcpy(&fa, ra + 4 * i, 4);
            std::memcpy(&fb, rb + 4 * i, 4);
            if (!std::isfinite(fa) || !std::isfinite(fb)) {
                if (std::memcmp(&fa, &fb, 4) != 0) worst = std::numeric_limits<double>::infinity();
                continue;
            }
            worst = std::max(worst, std::abs(double(fa) - double(fb)) / std::max(1.0, std::abs(double(fa))));
        }
    }
    return worst;
}

/// Runs `frames` frames of `json` on cpu and emulated at 1 and 2 threads; every field must be the same bits, but
/// those `tolerance` names (field -> bound of difference()). The passes' stats must agree as well.
void expectEmulatedMatchesCpu(const nlohmann::json& json, int frames,
                              const std::map<std::string, double>& tolerance = {}, bool sameStats = true) {
    for (unsigned threads : {1u, 2u}) {
        ThreadLimit limit(threads);
        auto cpu = graphOn(json, "cpu", 45, 29), emulated = graphOn(json, "emulated", 45, 29);
        for (int f = 0; f < frames; ++f) {
            const FrameInfo frame{uint64_t(f), f / 30.0, nullptr, nullptr};
            cpu->execute(frame);
            emulated->execute(frame);
            for (const std::string& field : fieldsOf(*cpu)) {
                const Texture* a = cpu->fieldTexture(field);
                const Texture* b = emulated->fieldTexture(field);
                ASSERT_TRUE(a && b) << field;
                const auto bound = tolerance.find(field);
                if (bound == tolerance.end())
                    EXPECT_TRUE(test::sameBits(*a, *b)) << field << " frame " << f << " threads " << threads;
                else
                    EXPECT_LE(difference(*a, *b), bound->second) << field << " frame " << f << " threads " << threads;
            }
            if (sameStats) EXPECT_EQ(cpu->lastStats(), emulated->lastStats()) << "frame " << f;
        }
    }
}

nlohmann::json sourceInto(const nlohmann::json& pass, const std::vector<std::string>& outputs,
                          const std::string& srcInput) {
    return {{"loom_graph", 1},
            {"name", "t"},
            {"passes", {{{"name", "Src"}, {"type", "FunctionSource"}}, pass}},
            {"edges", nlohmann::json::array({nlohmann::json::array({"Src.color", srcInput})})},
            {"outputs", outputs}};
}

}  // namespace

// The placement itself: each of the three passes runs where it was asked to, on emulated.
TEST(DevicePasses, ToneMapAccumulateAndTaaArePlacedOnEmulated) {
    const nlohmann::json g = {
        {"loom_graph", 1},
        {"name", "t"},
        {"passes",
         {{{"name", "Src"}, {"type", "MotionSource"}},
          {{"name", "TAA"}, {"type", "TAAPass"}},
          {{"name", "Accumulate"}, {"type", "AccumulatePass"}},
          {{"name", "ToneMap"}, {"type", "ToneMap"}}}},
        {"edges", nlohmann::json::array({nlohmann::json::array({"Src.color", "TAA.colorIn"}),
                                         nlohmann::json::array({"TAA.colorOut", "Accumulate.src"}),
                                         nlohmann::json::array({"Accumulate.dst", "ToneMap.src"})})},
        {"outputs", {"ToneMap.dst"}}};
    auto emulated = graphOn(g, "emulated", 16, 8);
    for (const PlacedPass& p : emulated->plan().placement)
        EXPECT_EQ(p.device, p.name == "Src" ? DeviceKind::Cpu : DeviceKind::Emulated) << p.name;
}

// ToneMap without auto exposure: the device's mapping is the CPU's, bit for bit, for every operator.
TEST(DevicePasses, ToneMapOnEmulatedEqualsCpuBitForBit) {
    for (const char* op : {"linear", "reinhard", "modifiedReinhard", "aces", "hable"}) {
        SCOPED_TRACE(op);
        expectEmulatedMatchesCpu(
            sourceInto({{"name", "ToneMap"}, {"type", "ToneMap"}, {"params", {{"operator", op}, {"exposure", 0.5}}}},
                       {"ToneMap.dst", "ToneMap.dstFloat"}, "ToneMap.src"),
            3);
    }
}

// Auto exposure (immediate on the first frame, then adapting over time): the log-average is summed in another
// order on the device, so the state and the images agree to the tolerance stated at the top.
TEST(DevicePasses, ToneMapAutoExposureOnEmulatedMatchesCpu) {
    expectEmulatedMatchesCpu(
        sourceInto(
            {{"name", "ToneMap"}, {"type", "ToneMap"}, {"params", {{"autoExposure", true}, {"adaptationTime", 0.05}}}},
            {"ToneMap.dst", "ToneMap.dstFloat"}, "ToneMap.src"),
        5,
        {{"ToneMap.adaptedLuminance", 1e-5},
         {"ToneMap.adaptedLuminance@prev", 1e-5},
         {"ToneMap.dst", 1.0},
         {"ToneMap.dstFloat", 1e-5}},
        false);
}

// Every precision, with the denoised blend and the partial outputs, non-finite and huge samples: bit for bit,
// history and stats included.
TEST(DevicePasses, AccumulateOnEmulatedEqualsCpuBitForBit) {
    for (const char* precision : {"float", "kahan", "double"}) {
        SCOPED_TRACE(precision);
        nlohmann::json g = sourceInto(
            {{"name", "Accumulate"}, {"type", "AccumulatePass"}, {"params", {{"precision", precision}}}},
            {"Accumulate.dst", "Accumulate.partialSumRG", "Accumulate.partialSumBA", "Accumulate.partialCount"},
            "Accumulate.src");
        expectEmulatedMatchesCpu(g, 4);
        g["passes"].push_back({{"name", "Den"}, {"type", "FunctionSource"}});
        g["edges"].push_back(nlohmann::json::array({"Den.color", "Accumulate.denoised"}));
        g["passes"][1]["params"]["maxFrames"] = 3;  // frozen on the last frame
        expectEmulatedMatchesCpu(g, 5);
    }
}

// TAA on emulated runs the reference kernel: equal to the CPU's `reference` bit for bit, and within the vector
// path's stated tolerance of the CPU's default path, over 6 frames of feedback (history on the device).
TEST(DevicePasses, TaaOnEmulatedEqualsCpuReference) {
    for (bool hdrCompress : {false, true}) {
        SCOPED_TRACE(hdrCompress);
        const auto graph = [&](bool reference) {
            return nlohmann::json{
                {"loom_graph", 1},
                {"name", "t"},
                {"passes",
                 {{{"name", "Src"}, {"type", "MotionSource"}},
                  {{"name", "TAA"},
                   {"type", "TAAPass"},
                   {"params", {{"reference", reference}, {"hdrCompress", hdrCompress}}}}}},
                {"edges", nlohmann::json::array({nlohmann::json::array({"Src.color", "TAA.colorIn"})})},
                {"outputs", {"TAA.colorOut"}}};
        };
        expectEmulatedMatchesCpu(graph(true), 6);
        expectEmulatedMatchesCpu(graph(false), 6,
                                 {{"TAA.colorOut", 1e-4}, {"TAA.colorHistory", 1e-4}, {"TAA.colorHistory@prev", 1e-4}},
                                 false);
    }
}

// The shipped default graphs on cornell_dynamic at 64x64: the ported passes on emulated, the others on the CPU with
// transfers where a field crosses. ToneMap's output (no auto exposure there) and every observed field is the CPU's
// bit for bit, but TAA's, which runs its reference kernel against the CPU's vector path (1e-4 of max(1, |v|)), and
// what takes it in downstream (Accumulate.dst blends it; ToneMap.dst within one 8-bit step).
TEST(DevicePasses, ShippedDefaultGraphsOnEmulatedMatchCpu) {
    for (const char* name : {"PathTracerSVGF", "PathTracerSVGFTAA"}) {
        SCOPED_TRACE(name);
        const std::string path = std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/" + name + ".json";
        const bool taa = std::string(name).find("TAA") != std::string::npos;
        for (unsigned threads : {1u, 2u}) {
            ThreadLimit limit(threads);
            auto scene = Scene::load(test::dataScene("cornell_dynamic.gltf"));
            CompileOptions o;
            o.width = o.height = 64;
            o.device = "cpu";
            std::ifstream in(path);
            const std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
            auto cpu = std::make_unique<RenderGraph>(parseGraph(text, path), test::pluginRegistry());
            auto emulated = std::make_unique<RenderGraph>(parseGraph(text, path), test::pluginRegistry());
            cpu->setScene(scene);
            emulated->setScene(scene);
            cpu->compile(o);
            o.device = "emulated";
            emulated->compile(o);
            for (uint64_t f = 0; f < 3; ++f) {
                const double t = f / 30.0;
                scene->update(t);
                cpu->execute(FrameInfo{f, t, scene.get(), &scene->camera});
                emulated->execute(FrameInfo{f, t, scene.get(), &scene->camera});
                const Texture* a = cpu->fieldTexture("ToneMap.dst");
                const Texture* b = emulated->fieldTexture("ToneMap.dst");
                ASSERT_TRUE(a && b);
                if (taa)
                    EXPECT_LE(difference(*a, *b), 1.0) << "frame " << f << " threads " << threads;
                else
                    EXPECT_TRUE(test::sameBits(*a, *b)) << "frame " << f << " threads " << threads;
            }
        }
    }
}
