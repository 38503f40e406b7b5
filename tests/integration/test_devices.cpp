// Devices in the graph: passes placed on the emulated device (the GPU path on CPU threads, its memory kept apart)
// give the CPU's results bit for bit, with a transfer exactly where a field crosses devices and nowhere else; device
// memory read without a transfer fails where it is read; cuda without a GPU is refused for a run and planned for
// `loom check`. The test passes Blur, FrameCounter and Add run on cpu and emulated; Pattern and ToSrgb8 on cpu only.
#include <gtest/gtest.h>
#include <unistd.h>

#include <filesystem>
#include <fstream>
#include <map>
#include <string>
#include <vector>

#include "TestUtil.h"
#include "loom/Device.h"
#include "loom/Error.h"
#include "loom/Launch.h"
#include "loom/RenderGraph.h"

using namespace loom;
namespace fs = std::filesystem;

#define EXPECT_CONTAINS(text, part) \
    EXPECT_NE(std::string(text).find(part), std::string::npos) << "'" << (part) << "' not in:\n" << (text)

namespace {

const std::string kTestPattern = std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/TestPattern.json";

nlohmann::json testPatternJson() {
    std::ifstream in(kTestPattern);
    return nlohmann::json::parse(in);
}

std::unique_ptr<RenderGraph> testPattern(const std::string& device, const nlohmann::json& edit = nullptr) {
    nlohmann::json g = testPatternJson();
    if (!edit.is_null()) g.merge_patch(edit);
    CompileOptions o;
    o.device = device;
    o.observe = {"*"};
    return test::compiledGraph(g, nullptr, 37, 23, o);
}

std::vector<std::string> allFields(const RenderGraph& g) {
    std::vector<std::string> out;
    for (const auto& r : g.plan().resources)
        if (r.name.find(' ') == std::string::npos) out.push_back(r.name);  // not the transfer copies
    return out;
}

}  // namespace

// Every field of every frame (history included) on emulated equals the CPU's bit for bit, at 1 and 2 threads.
TEST(Devices, EmulatedEqualsCpuBitForBit) {
    for (unsigned threads : {1u, 2u}) {
        ThreadLimit limit(threads);
        auto cpu = testPattern("cpu"), emulated = testPattern("emulated");
        for (uint64_t f = 0; f < 3; ++f) {
            cpu->execute(FrameInfo{f, double(f) / 30.0, nullptr, nullptr});
            emulated->execute(FrameInfo{f, double(f) / 30.0, nullptr, nullptr});
            for (const std::string& field : allFields(*cpu)) {
                const Texture* a = cpu->fieldTexture(field);
                const Texture* b = emulated->fieldTexture(field);
                ASSERT_TRUE(a && b) << field;
                ASSERT_TRUE(b->onHost()) << field << ": fieldTexture gives the host copy";
                EXPECT_TRUE(a->samePixels(*b)) << field << " frame " << f << " threads " << threads;
            }
        }
        // The frame counter's history lived on the device across frames.
        EXPECT_EQ(emulated->fieldTexture("Counter.dst")->texel(5, 5, 0), 3.f);
    }
}

// A transfer exactly where a field crosses devices: the CPU-only pattern into the emulated blur, the emulated mix
// into the CPU-only display; host copies of what leaves the device for the observer; nothing on the CPU graph.
TEST(Devices, TransfersOnlyWhereAFieldCrossesDevices) {
    auto g = testPattern("emulated");
    const CompiledPlan& p = g->plan();
    std::map<std::string, DeviceKind> placed;
    for (const PlacedPass& pp : p.placement) placed[pp.name] = pp.device;
    EXPECT_EQ(placed["Pattern"], DeviceKind::Cpu);
    EXPECT_EQ(placed["Blur"], DeviceKind::Emulated);
    EXPECT_EQ(placed["Counter"], DeviceKind::Emulated);
    EXPECT_EQ(placed["Mix"], DeviceKind::Emulated);
    EXPECT_EQ(placed["Display"], DeviceKind::Cpu);
    std::vector<std::string> into;
    for (const TransferInfo& t : p.transfers)
        if (!t.after) into.push_back(t.field + " " + deviceName(t.from) + ">" + deviceName(t.to) + " " + t.reason);
    EXPECT_EQ(into, (std::vector<std::string>{"Pattern.dst cpu>emulated for Blur", "Mix.dst emulated>cpu for Display"}));
    for (const TransferInfo& t : p.transfers)
        if (t.after) EXPECT_NE(placed[t.field.substr(0, t.field.find('.'))], DeviceKind::Cpu) << t.field;
    EXPECT_GT(p.devicePeakBytes[size_t(DeviceKind::Emulated)], 0u);
    EXPECT_GT(p.deviceHistoryBytes[size_t(DeviceKind::Emulated)], 0u);  // the counter's history
    EXPECT_TRUE(testPattern("cpu")->plan().transfers.empty());
    // A pass the graph pins to the CPU moves the crossings: Blur on cpu reads the pattern directly.
    nlohmann::json g2 = testPatternJson();
    g2["passes"][1]["device"] = "cpu";
    CompileOptions o;
    o.device = "emulated";
    auto moved = test::compiledGraph(g2, nullptr, 16, 16, o);
    for (const TransferInfo& t : moved->plan().transfers)
        if (!t.after) EXPECT_NE(t.field, "Pattern.dst") << "Blur runs on the CPU";
}

// Device memory is reached only through device views and transfers: a pass that reads its input through a host
// view fails on the emulated device, naming the pass, and runs on the CPU.
TEST(Devices, AHostReadOfDeviceMemoryFailsNamingThePass) {
    nlohmann::json g = testPatternJson();
    g["passes"][3]["params"]["readHostView"] = true;
    CompileOptions o;
    o.device = "emulated";
    auto bad = test::compiledGraph(g, nullptr, 16, 16, o);
    try {
        bad->execute(FrameInfo{});
        FAIL() << "a host view of emulated memory was allowed";
    } catch (const Error& e) {
        EXPECT_EQ(e.info().where, "Mix");
        EXPECT_CONTAINS(e.what(), "lives on the emulated device");
    }
    o.device = "cpu";
    auto fine = test::compiledGraph(g, nullptr, 16, 16, o);
    EXPECT_NO_THROW(fine->execute(FrameInfo{}));
}

// Out of device memory is bad input naming the field and its bytes.
TEST(Devices, OutOfDeviceMemoryNamesTheFieldAndBytes) {
    try {
        (void)allocateOnDevice(DeviceKind::Emulated, size_t(1) << 62, "SVGF.illumination");
        FAIL() << "2^62 bytes were allocated";
    } catch (const Error& e) {
        EXPECT_EQ(e.kind(), ErrorKind::BadInput);
        EXPECT_CONTAINS(e.what(), "SVGF.illumination");
        EXPECT_CONTAINS(e.what(), "4611686018427387904 bytes");
    }
}

// launch2D visits every pixel once; reduceRows sums in a fixed order, so cpu and emulated agree bit for bit and
// the result does not depend on the thread count.
TEST(Devices, LaunchAndReduceAgreeOnEveryDeviceAndThreadCount) {
    const uint32_t w = 67, h = 45;
    for (DeviceKind d : {DeviceKind::Cpu, DeviceKind::Emulated}) {
        Texture t = Texture::onDevice(d, w, h, Format::R32F);
        const auto v = t.deviceView<float>();
        launch2D(d, w, h, [=](uint32_t x, uint32_t y) { v.at(x, y) += 0.1f * float(x) + 1e-3f * float(y * y); });
        Texture host(w, h, Format::R32F);
        copyTexture(host, t);
        double expect = 0.0;
        for (uint32_t y = 0; y < h; ++y)
            for (uint32_t x = 0; x < w; ++x) EXPECT_EQ(host.texel(x, y, 0), 0.1f * float(x) + 1e-3f * float(y * y));
        float sums[2];
        for (unsigned threads : {1u, 2u}) {
            ThreadLimit limit(threads);
            sums[threads - 1] = reduceRows(
                d, w, h, 0.f, [=](uint32_t x, uint32_t y) { return v.at(x, y); }, [](float a, float b) { return a + b; });
        }
        for (uint32_t y = 0; y < h; ++y) {
            float row = 0.f;
            for (uint32_t x = 0; x < w; ++x) row += host.texel(x, y, 0);
            expect = double(float(expect) + row);
        }
        EXPECT_EQ(sums[0], sums[1]);
        EXPECT_EQ(sums[0], float(expect));
    }
}

// cuda with no usable GPU: a run is refused naming the reason; `loom check` plans it without one.
TEST(Devices, CudaWithoutAGpuIsRefusedForARunAndPlannedForACheck) {
    if (cudaStatus().usable) GTEST_SKIP() << "a CUDA device is present: " << cudaStatus().description;
    const fs::path dir = fs::temp_directory_path() / ("loom_devices_" + std::to_string(::getpid()));
    fs::create_directories(dir);
    const test::CliResult run =
        test::runLoom(dir, "render --graph " + test::shellQuoted(kTestPattern) + " --size 16x16 --device cuda");
    EXPECT_EQ(run.code, 2) << run.output;
    EXPECT_CONTAINS(run.output, "device 'cuda' was asked for, and ");
    const test::CliResult check = test::runLoom(dir, "check " + test::shellQuoted(kTestPattern) + " --device cuda");
    EXPECT_EQ(check.code, 0) << check.output;
    EXPECT_CONTAINS(check.output, "Devices:");
    EXPECT_CONTAINS(check.output, "has no cuda version: runs on the CPU");
    const test::CliResult unknown =
        test::runLoom(dir, "render --graph " + test::shellQuoted(kTestPattern) + " --size 16x16 --device emulate");
    EXPECT_EQ(unknown.code, 2) << unknown.output;
    EXPECT_CONTAINS(unknown.output, "did you mean 'emulated'");
    fs::remove_all(dir);
}

// The graph file's "device", for the graph and per pass: read, written back, and a wrong one refused.
TEST(Devices, GraphFilesNameDevices) {
    nlohmann::json g = testPatternJson();
    g["device"] = "emulated";
    g["passes"][1]["device"] = "cpu";
    const GraphDesc d = parseGraph(g.dump());
    EXPECT_EQ(d.device, "emulated");
    EXPECT_EQ(d.passes[1].device, "cpu");
    EXPECT_TRUE(parseGraph(graphToJson(d).dump()).sameAs(d));
    g["passes"][1]["device"] = "gpu";
    try {
        (void)parseGraph(g.dump(), "g.json");
        FAIL() << "device 'gpu' was read";
    } catch (const Error& e) {
        EXPECT_EQ(e.info().where, "/passes/1/device");
        EXPECT_CONTAINS(e.what(), "auto, cpu, cuda, emulated");
    }
}

// `loom render --device emulated --dump '*'` writes the same files as on the CPU, byte for byte: dumps of fields
// off the host come from their host copies.
TEST(Devices, EmulatedDumpsEqualTheCpusFiles) {
    const fs::path dir = fs::temp_directory_path() / ("loom_devices_dump_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    for (const char* device : {"cpu", "emulated"}) {
        const test::CliResult r = test::runLoom(dir, "render --graph " + test::shellQuoted(kTestPattern) +
                                                         " --size 24x16 --frames 2 --dump '*' -q --device " + device +
                                                         " --out " + device);
        ASSERT_EQ(r.code, 0) << r.output;
    }
    size_t compared = 0;
    for (const auto& e : fs::directory_iterator(dir / "cpu")) {
        const fs::path other = dir / "emulated" / e.path().filename();
        ASSERT_TRUE(fs::exists(other)) << other;
        std::ifstream a(e.path(), std::ios::binary), b(other, std::ios::binary);
        const std::string x((std::istreambuf_iterator<char>(a)), {}), y((std::istreambuf_iterator<char>(b)), {});
        EXPECT_TRUE(x == y) << e.path().filename();
        ++compared;
    }
    EXPECT_GE(compared, 2u * 9u);  // two frames of every field
    fs::remove_all(dir);
}
