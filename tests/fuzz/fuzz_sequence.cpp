// In-process fuzzing of what ImageSequence does to the values a sequence's files hold (SequenceConversions.h):
// random and extreme camera matrices (infinite, NaN, 3e38, singular, scaled by 1e-30 .. 1e30), and depth, normals,
// motion, albedo and colour samples drawn from finite-but-extreme values (+-1e38, +-FLT_MAX, denormals), NaN,
// infinities and ordinary ones, through every conversion setting. Then SVGF's demodulation and remodulation of such
// colour, albedo and emission (SVGFKernels.h). The contract checked on every input:
//   - a camera matrix is refused with a loom::Error of the bad-input kind (exit code 2 in the CLI), or it is used;
//   - every value convertFrame() leaves is finite, and in its channel's range: unit or zero normals (w = 0), a
//     depth that is a miss (-1, slope 0) or positive, albedos in [0, kMaxReflectance], motion within
//     +-kMaxMotionUv; the replacements it reports are no more than the samples it was given;
//   - SVGF's remodulated colour is finite for finite colour and any albedo and emission.
// Seeded: the same --seed and --iterations give the same inputs.
//
// Usage: loom_fuzz_sequence [--seed N] [--iterations N]
// Exit code 0 when every input kept the contract, 1 when any did not (each finding is printed).
#include <spdlog/spdlog.h>

#include <cfloat>
#include <cmath>
#include <cstdio>
#include <limits>
#include <optional>
#include <random>
#include <string>

#include "../../passes/ImageSequence/SequenceConversions.h"
#include "../../passes/SVGF/SVGFKernels.h"
#include "loom/Error.h"

using namespace loom;

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();
const float kNaN = std::numeric_limits<float>::quiet_NaN();

class Fuzzer {
public:
    explicit Fuzzer(unsigned seed) : mRng(seed) {}

    /// One input through the conversions and SVGF's modulation; returns the findings' descriptions.
    void iterate(long iteration) {
        mIteration = iteration;
        convertOneFrame();
        modulateSamples();
    }

    long findings() const { return mFindings; }
    long refused() const { return mRefused; }

private:
    int pick(int n) { return std::uniform_int_distribution<int>(0, n - 1)(mRng); }
    bool chance(double p) { return std::bernoulli_distribution(p)(mRng); }
    float uniform(float lo, float hi) { return std::uniform_real_distribution<float>(lo, hi)(mRng); }

    /// A sample: mostly ordinary, else one of the values that break arithmetic.
    float sample(float lo, float hi) {
        static const float kExtreme[] = {0.f,     -0.f,    1e38f,  -1e38f, FLT_MAX, -FLT_MAX, 3e38f,   -3e38f,
                                         1e-40f,  -1e-40f, 1e-45f, kNaN,   kInf,    -kInf,    1e10f,   -1e10f,
                                         FLT_MIN, 1e19f,   -1e19f, 1e-20f, 1.f,     -1.f,     4.0001f, 1e6f};
        if (chance(0.6)) return uniform(lo, hi);
        if (chance(0.2)) return std::ldexp(uniform(-1.f, 1.f), pick(260) - 130);
        return kExtreme[pick(int(std::size(kExtreme)))];
    }

    Texture texture(uint32_t w, uint32_t h, Format format, float lo, float hi) {
        Texture t(w, h, format);
        const uint32_t channels = formatInfo(format).channels;
        for (uint32_t y = 0; y < h; ++y) {
            auto* row = reinterpret_cast<float*>(t.row(y));
            for (uint32_t i = 0; i < w * channels; ++i) row[i] = sample(lo, hi);
        }
        return t;
    }

    std::array<float, 16> matrix() {
        // A rotation about a random axis, a translation, then damage of one kind.
        const glm::vec3 axis = sequence::normalizedOrZero({uniform(-1, 1), uniform(-1, 1), uniform(-1, 1)});
        const float angle = uniform(-4.f, 4.f), c = std::cos(angle), s = std::sin(angle), t = 1.f - c;
        std::array<float, 16> m = {t * axis.x * axis.x + c,
                                   t * axis.x * axis.y - s * axis.z,
                                   t * axis.x * axis.z + s * axis.y,
                                   0.f,
                                   t * axis.x * axis.y + s * axis.z,
                                   t * axis.y * axis.y + c,
                                   t * axis.y * axis.z - s * axis.x,
                                   0.f,
                                   t * axis.x * axis.z - s * axis.y,
                                   t * axis.y * axis.z + s * axis.x,
                                   t * axis.z * axis.z + c,
                                   0.f,
                                   uniform(-100, 100),
                                   uniform(-100, 100),
                                   uniform(-100, 100),
                                   1.f};
        switch (pick(6)) {
            case 0:
                break;  // a proper camera
            case 1: {   // scaled by anything from 1e-30 to 1e30
                const float scale = std::pow(10.f, uniform(-30.f, 30.f));
                for (int i = 0; i < 12; ++i) m[size_t(i)] *= scale;
                break;
            }
            case 2:  // singular: a row repeated, or zero
                for (int k = 0; k < 4; ++k) m[size_t(4 + k)] = chance(0.5) ? m[size_t(k)] : 0.f;
                break;
            default:  // entries replaced by extreme values
                for (int n = 1 + pick(3); n > 0; --n) m[size_t(pick(16))] = sample(-1e3f, 1e3f);
                break;
        }
        return m;
    }

    void finding(const std::string& what) {
        ++mFindings;
        if (mFindings <= 20) std::printf("finding at iteration %ld: %s\n", mIteration, what.c_str());
    }

    void convertOneFrame() {
        const uint32_t w = 1 + uint32_t(pick(6)), h = 1 + uint32_t(pick(5));
        sequence::ConversionSettings s;
        s.depthFromOneChannel = chance(0.5);
        static const float kMissDepths[] = {1e9f, 3.4e38f, 1e-3f, 10.f};
        s.missDepth = kMissDepths[pick(4)];
        s.motion = sequence::MotionKind(pick(3));
        s.motionYUp = chance(0.5);
        if (chance(0.5)) {
            s.worldToCamera = matrix();
            try {
                sequence::requireUsableWorldToCamera(*s.worldToCamera, "Frames.normals", "frame.exr");
            } catch (const Error& e) {
                if (e.kind() != ErrorKind::BadInput || std::string(e.what()).empty())
                    finding(std::string("a camera matrix refused with the wrong kind of error: ") + e.what());
                ++mRefused;
                return;
            }
        }
        Texture normW = texture(w, h, Format::RGBA32F, -2.f, 2.f);
        Texture linearZ = texture(w, h, Format::RG32F, -1.f, 100.f);
        Texture mvec = texture(w, h, Format::RG32F, -50.f, 50.f);
        Texture albedo = texture(w, h, Format::RGBA32F, 0.f, 1.f);
        Texture specAlbedo = texture(w, h, Format::RGBA32F, 0.f, 1.f);
        Texture color = texture(w, h, Format::RGBA32F, 0.f, 100.f);
        sequence::FrameChannels f;
        f.normW = &normW;
        f.linearZ = &linearZ;
        f.mvec = &mvec;
        f.reflectances = {&albedo, &specAlbedo};
        f.others = {&color};
        const sequence::Replaced replaced = sequence::convertFrame(f, s);
        const uint64_t samples = uint64_t(w) * h * (4 * 4 + 2 * 2);
        if (replaced.nonFinite > samples || replaced.outOfRange > samples) finding("more replacements than samples");
        for (uint32_t y = 0; y < h; ++y)
            for (uint32_t x = 0; x < w; ++x) {
                const glm::vec4 n = normW.view<glm::vec4>().at(x, y);
                const float len = glm::length(glm::vec3(n));
                if (!isFinite(n) || n.w != 0.f || !(len == 0.f || std::fabs(len - 1.f) <= 2e-3f))
                    finding("a normal that is not unit or zero: " + fmt::format("{} {} {} {}", n.x, n.y, n.z, n.w));
                const glm::vec2 z = linearZ.view<glm::vec2>().at(x, y);
                if (!isFinite(z) || !((z.x > 0.f && z.y >= 0.f) || z == glm::vec2(-1.f, 0.f)))
                    finding(fmt::format("a linearZ that is neither a miss nor a surface: {} {}", z.x, z.y));
                const glm::vec2 m = mvec.view<glm::vec2>().at(x, y);
                if (!isFinite(m) || std::fabs(m.x) > sequence::kMaxMotionUv || std::fabs(m.y) > sequence::kMaxMotionUv)
                    finding(fmt::format("a motion out of range: {} {}", m.x, m.y));
                for (const Texture* a : {&albedo, &specAlbedo}) {
                    const glm::vec4 v = a->view<glm::vec4>().at(x, y);
                    for (int c = 0; c < 4; ++c)
                        if (!(v[c] >= 0.f && v[c] <= sequence::kMaxReflectance))
                            finding(fmt::format("an albedo out of range: {}", v[c]));
                }
                if (!isFinite(color.view<glm::vec4>().at(x, y))) finding("a colour that is not finite");
            }
    }

    /// SVGF's per-pixel demodulation (temporalPixel) and remodulation (remodulate) of finite colour and any albedo
    /// and emission, with the illumination anywhere in the range the filter keeps.
    void modulateSamples() {
        for (int k = 0; k < 8; ++k) {
            glm::vec4 color(sample(0.f, 100.f), sample(0.f, 100.f), sample(0.f, 100.f), sample(0.f, 1.f));
            for (int c = 0; c < 3; ++c)
                if (!std::isfinite(color[c])) color[c] = FLT_MAX;  // SVGF rejects non-finite samples before
            const glm::vec4 albedo(sample(0.f, 1.f), sample(0.f, 1.f), sample(0.f, 1.f), 1.f);
            const glm::vec3 emission(sample(0.f, 10.f), sample(0.f, 10.f), sample(0.f, 10.f));
            const glm::vec3 l = svgf::clampIllumination((glm::vec3(color) - svgf::finiteOrZero(emission)) /
                                                        svgf::guardedAlbedo(albedo));
            const glm::vec3 filtered = chance(0.5) ? l : glm::vec3(uniform(0.f, svgf::kMaxIllumination));
            const glm::vec4 out = svgf::remodulate(filtered, color, albedo, emission, chance(0.9) ? 1.f : -1.f);
            if (!isFinite(l) || !isFinite(out))
                finding(
                    fmt::format("SVGF's modulation of colour {} {} {}, albedo {} {} {}, emission {} {} {}: {} {} {}",
                                color.r, color.g, color.b, albedo.r, albedo.g, albedo.b, emission.r, emission.g,
                                emission.b, out.r, out.g, out.b));
        }
    }

    std::mt19937 mRng;
    long mIteration = 0;
    long mFindings = 0;
    long mRefused = 0;
};

}  // namespace

int main(int argc, char** argv) {
    unsigned seed = 1;
    long iterations = 1000;
    for (int i = 1; i + 1 < argc; i += 2) {
        const std::string a = argv[i], v = argv[i + 1];
        if (a == "--seed")
            seed = unsigned(std::stoul(v));
        else if (a == "--iterations")
            iterations = std::stol(v);
        else {
            std::fprintf(stderr, "unknown option %s\n", a.c_str());
            return 2;
        }
    }
    spdlog::set_level(spdlog::level::off);
    Fuzzer fuzzer(seed);
    for (long i = 0; i < iterations; ++i) fuzzer.iterate(i);
    std::printf("%ld executions (seed %u): %ld camera matrices refused as bad input, %ld findings\n", iterations, seed,
                fuzzer.refused(), fuzzer.findings());
    return fuzzer.findings() == 0 ? 0 : 1;
}
