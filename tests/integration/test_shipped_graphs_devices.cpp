// Every shipped graph renders with --device emulated: passes with a device version run there (their fields in the
// emulated device's memory), the others on the CPU, and the graph copies what crosses. The outputs do not depend on
// the thread count (bit for bit) and equal the CPU's: bit for bit where the same functors run, within a small
// tolerance where the CPU runs a Highway twin of a functor (docs/KERNELS.md).
#include <gtest/gtest.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>

#include "TestUtil.h"
#include "loom/ImageIO.h"

using namespace loom;
namespace fs = std::filesystem;

namespace {

std::string bytesOf(const fs::path& p) {
    std::ifstream in(p, std::ios::binary);
    return std::string((std::istreambuf_iterator<char>(in)), {});
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
            const Texture a = readImage(f.path()), b = readImage(e1);
            ASSERT_EQ(a.format(), b.format()) << f.path().filename();
            const bool eightBit = a.format() == Format::RGBA8Unorm || a.format() == Format::RGBA8Srgb;
            double largest = 0.0;
            for (uint32_t y = 0; y < a.height(); ++y)
                for (uint32_t x = 0; x < a.width(); ++x)
                    for (uint32_t c = 0; c < 4; ++c) {
                        const double u = a.texel(x, y, c), v = b.texel(x, y, c);
                        largest = std::max(largest, std::fabs(u - v) / (eightBit ? 1.0 : std::max(1.0, std::fabs(u))));
                    }
            // 8-bit: two steps of 255 at most; float: 1e-3 relative at most (the twins' stated bounds are tighter).
            EXPECT_LE(largest, eightBit ? 2.0 / 255.0 : 1e-3) << name << " " << f.path().filename();
            ++outputs;
        }
        EXPECT_GT(outputs, 0u) << name;
        ++graphs;
    }
    EXPECT_GE(graphs, 14u);
    fs::remove_all(dir);
}
