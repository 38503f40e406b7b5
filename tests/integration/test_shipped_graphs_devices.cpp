// Every shipped graph renders with --device emulated: passes with a device version run there (their fields in the
// emulated device's memory), the others on the CPU, and the graph copies what crosses. The outputs do not depend on
// the thread count (bit for bit) and equal the CPU's: bit for bit where the same functors run, within a small
// tolerance where the CPU runs a Highway twin of a functor (docs/KERNELS.md), and in all but a few seam pixels where
// the G-buffer is GBufferRT (Embree on the CPU, the BVH on a device).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <glm/glm.hpp>
#include <string>

#include "TestUtil.h"
#include "loom/Device.h"
#include "loom/DoubleTexels.h"
#include "loom/ImageIO.h"
#include "loom/Kernel.h"

using namespace loom;
namespace fs = std::filesystem;

namespace {

std::string bytesOf(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), {});
}

/// Compares an output of one run with the same output of another (`other`): within the tolerance at every pixel, or,
/// for a graph that traces rays on a device (`traced`), at all but 2 % of the pixels (see below). `what` names it.
void expectClose(const fs::path& reference, const fs::path& other, bool traced, const std::string& what) {
    const Texture a = readImage(reference), b = readImage(other);
    ASSERT_EQ(a.format(), b.format()) << what;
    const bool eightBit = a.format() == Format::RGBA8Unorm || a.format() == Format::RGBA8Srgb;
    // 8-bit: two steps of 255 at most; float: 1e-3 relative at most (the twins' stated bounds are tighter).
    const double tolerance = eightBit ? 2.0 / 255.0 : 1e-3;
    const std::string file = reference.filename().string();
    const bool vbuffer = a.format() == Format::RGBA32U && file.find("vbuffer") != std::string::npos;
    // AccumulatePass's partial sums hold two doubles a texel, as the (low, high) words of their bits.
    const bool doubles = a.format() == Format::RGBA32U && file.find("partialSum") != std::string::npos;
    double largest = 0.0;
    size_t beyond = 0;  // pixels with a channel beyond the tolerance
    for (uint32_t y = 0; y < a.height(); ++y)
        for (uint32_t x = 0; x < a.width(); ++x) {
            double pixel = 0.0;
            if (doubles) {
                const glm::dvec2 p = unpackDoublePair(a.view<glm::uvec4>().at(x, y));
                const glm::dvec2 q = unpackDoublePair(b.view<glm::uvec4>().at(x, y));
                for (int c = 0; c < 2; ++c)
                    pixel = std::max(pixel, std::fabs(p[c] - q[c]) / std::max(1.0, std::fabs(p[c])));
            }
            for (uint32_t c = 0; c < 4 && !doubles; ++c) {
                double u = a.texel(x, y, c), v = b.texel(x, y, c);
                if (vbuffer) {  // ids exactly, barycentrics as the floats their bits hold
                    const uint32_t p = a.view<glm::uvec4>().at(x, y)[c], q = b.view<glm::uvec4>().at(x, y)[c];
                    u = c < 2 ? double(p) : double(bitsToFloat(p));
                    v = c < 2 ? double(q) : double(bitsToFloat(q));
                }
                pixel = std::max(pixel, std::fabs(u - v) / (eightBit ? 1.0 : std::max(1.0, std::fabs(u))));
            }
            largest = std::max(largest, pixel);
            beyond += pixel > tolerance ? 1 : 0;
        }
    if (traced) {
        // Camera rays traced through Embree on the CPU and through the BVH on a device (test_bvh.cpp,
        // test_gbuffer_rt_devices.cpp): the same triangles with t and barycentrics a rounding apart, except
        // where a pixel's ray runs along the seam of two instances (a room's walls meeting): either wall is
        // right there, and the pixel's ids, normal and path-traced colour follow the one it sees (SVGF then
        // spreads that colour over its footprint, TAA over frames). A path tracer on the device also shades
        // with the scalar kernel where the CPU uses its SIMD twin, so a path's later decisions (Russian
        // roulette, a light pick) can go the other way a rounding apart (CudaKernelsOnHost: 99.6 % of
        // pixels within 1e-4). So a few pixels may differ beyond the tolerance: at most 2 % of them
        // (measured at 48x32 on cornell_dynamic: 4 seam pixels in GBufferRT's first frame, 17 pixels of its
        // denoised image; every other pixel of the G-buffer within 7e-6).
        EXPECT_LE(beyond, a.width() * a.height() / 50) << what << ": " << beyond
                                                       << " pixels differ, the largest by " << largest;
    } else {
        EXPECT_LE(largest, tolerance) << what;
    }
}

}  // namespace

TEST(ShippedGraphs, EveryGraphRendersOnEmulatedAsOnTheCpu) {
    const fs::path dir = fs::temp_directory_path() / ("loom_shipped_devices_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    const std::string source = LOOM_TEST_SOURCE_DIR;
    size_t graphs = 0;
    for (const auto& entry : fs::directory_iterator(source + "/graphs")) {
        const std::string name = entry.path().stem().string();
        // The sequence graph reads the shipped Blender frames (64x48); the test pattern needs no scene.
        // Graphs that trace rays on the device, through the scene's BVH where the CPU uses Embree: GBufferRT, or a
        // path tracer (see below).
        const std::string text = bytesOf(entry.path());
        const bool traced =
            text.find("\"GBufferRT\"") != std::string::npos || text.find("PathTracer\"") != std::string::npos;
        std::string args = "render --graph " + test::shellQuoted(entry.path().string()) + " --frames 3 -q";
        if (name == "DenoiseSequence")
            args += " --size 64x48 --set " +
                    test::shellQuoted("Frames.path=" + source + "/data/sequences/blender_cornell/noisy_####.exr");
        else if (name == "TestPattern")
            args += " --size 48x32";
        else
            args += " --size 48x32 --scene " + test::shellQuoted(test::dataScene("cornell_dynamic.gltf"));
        for (const char* run : {"cpu 1", "emulated 1", "emulated 2"}) {
            const std::string device(run, std::strchr(run, ' ')), threads(std::strchr(run, ' ') + 1);
            const test::CliResult r = test::runLoom(dir, args + " --device " + device + " --threads " + threads +
                                                             " --out " + name + "_" + device + "_" + threads);
            ASSERT_EQ(r.code, 0) << name << " on " << run << ":\n" << r.output;
        }
        size_t outputs = 0;
        for (const auto& f : fs::directory_iterator(dir / (name + "_cpu_1"))) {
            const fs::path e1 = dir / (name + "_emulated_1") / f.path().filename();
            const fs::path e2 = dir / (name + "_emulated_2") / f.path().filename();
            ASSERT_TRUE(fs::exists(e1) && fs::exists(e2)) << e1;
            EXPECT_TRUE(bytesOf(e1) == bytesOf(e2)) << f.path().filename() << ": emulated at 1 and 2 threads differ";
            expectClose(f.path(), e1, traced, name + " " + f.path().filename().string());
            ++outputs;
        }
        EXPECT_GT(outputs, 0u) << name;
        ++graphs;
    }
    EXPECT_GE(graphs, 14u);
    fs::remove_all(dir);
}

// With a usable GPU: the GPU variants of the default graphs on cuda give emulated's images, within the same bounds
// (the same functors; the GPU's own exp, log and pow round differently from the host's). Skipped without a GPU
// (scripts/gpu-check.sh runs it where one is lent).
TEST(ShippedGraphs, GpuGraphsOnCudaMatchEmulated) {
    if (!cudaStatus().usable) GTEST_SKIP() << "no CUDA device here: " << cudaStatus().description;
    const fs::path dir = fs::temp_directory_path() / ("loom_shipped_cuda_" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
    for (const char* name : {"PathTracerSVGF_GPU", "PathTracerSVGFTAA_GPU"}) {
        const std::string args = "render --graph " +
                                 test::shellQuoted(std::string(LOOM_TEST_SOURCE_DIR) + "/graphs/" + name + ".json") +
                                 " --frames 3 -q --size 96x64 --dump 'SVGF.*' --scene " +
                                 test::shellQuoted(test::dataScene("cornell_dynamic.gltf"));
        for (const char* device : {"emulated", "cuda"}) {
            const test::CliResult r =
                test::runLoom(dir, args + " --device " + device + " --out " + name + "_" + device);
            ASSERT_EQ(r.code, 0) << name << " on " << device << ":\n" << r.output;
        }
        size_t outputs = 0;
        for (const auto& f : fs::directory_iterator(dir / (std::string(name) + "_emulated"))) {
            const fs::path other = dir / (std::string(name) + "_cuda") / f.path().filename();
            ASSERT_TRUE(fs::exists(other)) << other;
            expectClose(f.path(), other, true, std::string(name) + " " + f.path().filename().string());
            ++outputs;
        }
        EXPECT_GT(outputs, 3u) << name;
    }
    fs::remove_all(dir);
}
