// Small passes that exercise the graph machinery before real passes exist,
// and that the demo renders. Each is simple enough to verify by hand.
#include <cmath>

#include <glm/glm.hpp>

#include "loom/Launch.h"
#include "loom/Parallel.h"
#include "loom/Plugin.h"

using namespace loom;

namespace {

const char kDst[] = "dst";
const char kSrc[] = "src";

/// The test passes whose kernels are launch2D functors run on the CPU and on the emulated device.
bool onHostOrEmulated(DeviceKind device) { return device == DeviceKind::Cpu || device == DeviceKind::Emulated; }

/// Fills dst with a constant colour.
class ConstantPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.output(kDst, Format::RGBA32F).doc("the constant colour");
    }
    void declareParams(ParamList& p) override {
        p.add("color", &mColor, glm::vec4(1.f)).doc("colour written to every pixel");
    }
    void execute(PassContext& ctx) override {
        auto dst = ctx.output(kDst)->view<glm::vec4>();
        parallelForPixels(dst.width, dst.height, [&](uint32_t x, uint32_t y) { dst.at(x, y) = mColor; });
    }

private:
    glm::vec4 mColor;
};

/// A smooth animated test pattern: radial rings and a gradient.
class PatternPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.output(kDst, Format::RGBA32F).doc("the pattern, linear HDR");
    }
    void declareParams(ParamList& p) override {
        p.add("frequency", &mFrequency, 12.f).range(0.f, 1000.f).doc("rings across the frame");
        p.add("speed", &mSpeed, 1.f).range(-100.f, 100.f).doc("ring phase change per second");
    }
    void execute(PassContext& ctx) override {
        auto dst = ctx.output(kDst)->view<glm::vec4>();
        const float phase = float(ctx.time()) * mSpeed;
        parallelForPixels(dst.width, dst.height, [&](uint32_t x, uint32_t y) {
            float u = (x + 0.5f) / dst.width, v = (y + 0.5f) / dst.height;
            float r = std::sqrt((u - 0.5f) * (u - 0.5f) + (v - 0.5f) * (v - 0.5f));
            float ring = 0.5f + 0.5f * std::cos(6.2831853f * (r * mFrequency - phase));
            dst.at(x, y) = glm::vec4(u * ring, v * ring, (1.f - u) * (1.f - ring) + 0.1f, 1.f);
        });
    }

private:
    float mFrequency, mSpeed;
};

/// dst = a * scaleA + b * scaleB.
class AddPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.input("a", Format::RGBA32F);
        r.input("b", Format::RGBA32F);
        r.output(kDst, Format::RGBA32F);
    }
    void declareParams(ParamList& p) override {
        p.add("scaleA", &mScaleA, 1.f).doc("weight of a");
        p.add("scaleB", &mScaleB, 1.f).doc("weight of b");
        p.add("readHostView", &mReadHostView, false)
            .doc("deliberately read input a through a host view (tests that device memory is reached only through "
                 "device views)");
    }
    bool runsOn(DeviceKind device) const override { return onHostOrEmulated(device); }
    void execute(PassContext& ctx) override {
        if (mReadHostView) (void)ctx.input("a")->view<glm::vec4>();
        const auto a = ctx.input("a")->deviceView<glm::vec4>();
        const auto b = ctx.input("b")->deviceView<glm::vec4>();
        const auto dst = ctx.output(kDst)->deviceView<glm::vec4>();
        const float sa = mScaleA, sb = mScaleB;
        launch2D(ctx.device(), dst.width, dst.height,
                 [=](uint32_t x, uint32_t y) { dst.at(x, y) = a.at(x, y) * sa + b.at(x, y) * sb; });
    }

private:
    float mScaleA, mScaleB;
    bool mReadHostView;
};

/// Separable box blur through an internal scratch texture (clamped edges).
class BlurPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.input(kSrc, Format::RGBA32F);
        r.output(kDst, Format::RGBA32F);
        r.internal("tmp", Format::RGBA32F).doc("horizontal pass result");
    }
    void declareParams(ParamList& p) override {
        p.add("radius", &mRadius, 2).range(0, 64).doc("box radius in pixels");
        p.add("readScratchFirst", &mReadScratchFirst, false)
            .doc("deliberately read the scratch texture before writing it (tests the NaN-poison mode)");
    }
    bool runsOn(DeviceKind device) const override { return onHostOrEmulated(device); }
    void execute(PassContext& ctx) override {
        const auto src = ctx.input(kSrc)->deviceView<glm::vec4>();
        const auto tmp = ctx.internal("tmp")->deviceView<glm::vec4>();
        const auto dst = ctx.output(kDst)->deviceView<glm::vec4>();
        const int w = int(src.width), h = int(src.height), rad = mRadius;
        const float norm = 1.f / float(2 * rad + 1);
        const bool bug = mReadScratchFirst;
        launch2D(ctx.device(), src.width, src.height, [=](uint32_t x, uint32_t y) {
            glm::vec4 sum(0.f);
            for (int k = -rad; k <= rad; ++k) sum += src.at(uint32_t(std::clamp(int(x) + k, 0, w - 1)), y);
            if (bug) sum += tmp.at(x, y) * 0.f;  // read before write: NaN * 0 = NaN in poison mode
            tmp.at(x, y) = sum * norm;
        });
        launch2D(ctx.device(), src.width, src.height, [=](uint32_t x, uint32_t y) {
            glm::vec4 sum(0.f);
            for (int k = -rad; k <= rad; ++k) sum += tmp.at(x, uint32_t(std::clamp(int(y) + k, 0, h - 1)));
            dst.at(x, y) = sum * norm;
        });
    }

private:
    int mRadius;
    bool mReadScratchFirst;
};

/// Counts frames in a history field: count = prev + 1 (1 when history is
/// invalid). dst shows the count in every channel.
class FrameCounterPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.history("count", Format::R32F).doc("frames since the last reset");
        r.output(kDst, Format::RGBA32F);
    }
    bool runsOn(DeviceKind device) const override { return onHostOrEmulated(device); }
    void execute(PassContext& ctx) override {
        const auto prev = ctx.historyPrev("count").deviceView<float>();
        const auto cur = ctx.historyCur("count").deviceView<float>();
        const auto dst = ctx.output(kDst)->deviceView<glm::vec4>();
        const bool valid = ctx.historyValid();
        launch2D(ctx.device(), dst.width, dst.height, [=](uint32_t x, uint32_t y) {
            float c = valid ? prev.at(x, y) + 1.f : 1.f;
            cur.at(x, y) = c;
            dst.at(x, y) = glm::vec4(c);
        });
    }
};

/// dst = src + bias (bias optional); the optional "mask" output is written
/// only when consumed.
class OptionalInputPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.input(kSrc, Format::RGBA32F);
        r.input("bias", Format::RGBA32F).optional();
        r.output(kDst, Format::RGBA32F);
        r.output("mask", Format::R32F).optional().doc("1 where src.r > 0.5");
    }
    void execute(PassContext& ctx) override {
        auto src = ctx.input(kSrc)->view<glm::vec4>();
        const Texture* biasTex = ctx.input("bias");
        auto dst = ctx.output(kDst)->view<glm::vec4>();
        Texture* maskTex = ctx.output("mask");
        parallelForPixels(dst.width, dst.height, [&](uint32_t x, uint32_t y) {
            glm::vec4 v = src.at(x, y);
            if (biasTex) v += biasTex->view<glm::vec4>().at(x, y);
            dst.at(x, y) = v;
            if (maskTex) maskTex->view<float>().at(x, y) = src.at(x, y).r > 0.5f ? 1.f : 0.f;
        });
        ctx.stats().add("biasConnected", biasTex ? 1 : 0);
        ctx.stats().add("maskWritten", maskTex ? 1 : 0);
    }
};

/// Records that it ran (stats "executed") and whether a parameter upstream changed ("inputParamsChanged") and,
/// when it has an input, copies it.
class ProbePass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.input(kSrc, Format::RGBA32F).optional();
        r.output("probe", Format::RGBA32F);
    }
    void execute(PassContext& ctx) override {
        ctx.stats().add("executed", 1);
        ctx.stats().set("inputParamsChanged", ctx.inputParamsChanged() ? 1 : 0);
        auto dst = ctx.output("probe")->view<glm::vec4>();
        const Texture* src = ctx.input(kSrc);
        parallelForPixels(dst.width, dst.height, [&](uint32_t x, uint32_t y) {
            dst.at(x, y) = src ? src->view<glm::vec4>().at(x, y) : glm::vec4(0.f);
        });
    }
};

/// Does nothing; used to measure scheduling overhead. With a scene, reports its skippedWork parameter as work left
/// out (for loom check).
class NoOpPass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.input(kSrc, Format::RGBA32F).optional();
        r.output(kDst, Format::RGBA32F).fixedSize(1, 1);
    }
    void declareParams(ParamList& p) override {
        p.add("skippedWork", &mSkippedWork, std::string()).doc("a line skippedWork() reports when a scene is set");
    }
    void execute(PassContext&) override {}
    void setScene(const std::shared_ptr<const Scene>& scene) override { mHasScene = scene != nullptr; }
    std::vector<std::string> skippedWork() const override {
        if (!mHasScene || mSkippedWork.empty()) return {};
        return {mSkippedWork};
    }

private:
    std::string mSkippedWork;
    bool mHasScene = false;
};

/// Converts linear RGBA32F to 8-bit sRGB for PNG output.
class ToSrgb8Pass final : public RenderPass {
public:
    void reflect(Reflection& r, const CompileInfo&) const override {
        r.input(kSrc, Format::RGBA32F);
        r.output(kDst, Format::RGBA8Srgb);
    }
    void execute(PassContext& ctx) override {
        auto src = ctx.input(kSrc)->view<glm::vec4>();
        auto dst = ctx.output(kDst)->view<glm::u8vec4>();
        auto encode = [](float c) {
            c = std::isfinite(c) ? std::clamp(c, 0.f, 1.f) : 0.f;
            float s = c <= 0.0031308f ? 12.92f * c : 1.055f * std::pow(c, 1.f / 2.4f) - 0.055f;
            return uint8_t(std::lround(s * 255.f));
        };
        parallelForPixels(dst.width, dst.height, [&](uint32_t x, uint32_t y) {
            glm::vec4 v = src.at(x, y);
            dst.at(x, y) = glm::u8vec4(encode(v.r), encode(v.g), encode(v.b), 255);
        });
    }
};

}  // namespace

LOOM_DEFINE_PLUGIN(registrar) {
    registrar.registerPass<ConstantPass>("Constant", "Fills its output with a constant colour (test pass).");
    registrar.registerPass<PatternPass>("Pattern", "Animated ring pattern (test pass).");
    registrar.registerPass<AddPass>("Add", "Weighted sum of two inputs (test pass).");
    registrar.registerPass<BlurPass>("Blur", "Separable box blur through an internal texture (test pass).");
    registrar.registerPass<FrameCounterPass>("FrameCounter", "Counts frames in a history field (test pass).");
    registrar.registerPass<OptionalInputPass>("OptionalInput", "An optional input and an optional output (test pass).");
    registrar.registerPass<ProbePass>("Probe", "Reports that it ran (test pass).");
    registrar.registerPass<NoOpPass>("NoOp", "Does nothing (scheduling benchmark).");
    registrar.registerPass<ToSrgb8Pass>("ToSrgb8", "Linear float to 8-bit sRGB (test pass).");
}
