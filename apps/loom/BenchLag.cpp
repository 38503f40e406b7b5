#include "BenchLag.h"

#include <fmt/format.h>

#include <algorithm>
#include <cmath>
#include <sstream>

#include "loom/Channels.h"
#include "loom/Metrics.h"
#include "loom/RenderGraph.h"

namespace loom::cli::bench {

namespace {

// The standard channels of the G-buffer the age tracker reads (docs/BENCH.md, "Lag").
using channel::kLinearZ;
using channel::kMeshId;
using channel::kMvec;

double meanOf(const std::vector<double>& v, size_t begin, size_t end) {
    double sum = 0.0;
    for (size_t i = begin; i < end; ++i) sum += v[i];
    return end > begin ? sum / double(end - begin) : 0.0;
}

/// The smoothed error at t: the mean over [t, t + w) without the window's largest value when w >= 3, so that one
/// outlying frame (a firefly) is no lag while a lasting excess is.
double smoothedAt(const std::vector<double>& v, size_t t, size_t w) {
    if (w < 3) return meanOf(v, t, t + w);
    const double largest = *std::max_element(v.begin() + ptrdiff_t(t), v.begin() + ptrdiff_t(t + w));
    double sum = 0.0;
    for (size_t i = t; i < t + w; ++i) sum += v[i];
    return (sum - largest) / double(w - 1);
}

bool finiteRgb(const glm::vec4& c) {
    return std::isfinite(c.x) && std::isfinite(c.y) && std::isfinite(c.z);
}

template <class T>
ImageView<const T> constView(const ImageView<T>& v) {
    return {v.data, v.width, v.height, v.rowPitch};
}

}  // namespace

Recovery recoverAfter(const std::vector<double>& errors, size_t event, size_t end, double tolerance, size_t window) {
    Recovery r;
    if (!(event < end && end <= errors.size())) return r;
    r.segmentFrames = end - event;
    const size_t lastHalf = event + (end - event) / 2;
    const size_t halfLength = end - lastHalf;
    r.steady = meanOf(errors, lastHalf, end);
    // Flat last half: its two halves agree within twice the tolerance (a curve still falling or rising is not
    // settled; per-frame noise of a few frames' means stays well inside).
    const size_t mid = lastHalf + halfLength / 2;
    r.settled = halfLength < 2 ||
                std::abs(meanOf(errors, lastHalf, mid) - meanOf(errors, mid, end)) <= 2.0 * tolerance * r.steady;
    if (!r.settled) return r;
    // Back for good: one past the last frame before the last half whose smoothed error is above the bound (the last
    // half itself is flat, so a settled segment always recovers, at most at its last half's start).
    const size_t w = std::max<size_t>(1, std::min(window, halfLength));
    const double bound = (1.0 + tolerance) * r.steady;
    size_t back = event;
    for (size_t t = event; t < lastHalf; ++t)
        if (smoothedAt(errors, t, w) > bound) back = t + 1;
    r.frames = back - event;
    return r;
}

std::vector<Recovery> frameRecoveries(const std::vector<double>& errors, uint64_t firstFrame,
                                      std::vector<uint32_t> events, double tolerance, size_t window) {
    std::vector<Recovery> out;
    if (errors.empty()) return out;
    std::sort(events.begin(), events.end());
    events.erase(std::unique(events.begin(), events.end()), events.end());
    std::vector<size_t> starts = {0};
    std::vector<std::string> kinds = {"cut"};
    for (uint32_t e : events) {
        if (e <= firstFrame || e - firstFrame >= errors.size()) continue;
        starts.push_back(size_t(e - firstFrame));
        kinds.push_back("light");
    }
    for (size_t i = 0; i < starts.size(); ++i) {
        const size_t end = i + 1 < starts.size() ? starts[i + 1] : errors.size();
        Recovery r = recoverAfter(errors, starts[i], end, tolerance, window);
        r.frame = firstFrame + starts[i];
        r.kind = kinds[i];
        out.push_back(std::move(r));
    }
    return out;
}

void updateAges(const AgeGBuffer& cur, ImageView<const uint32_t> prevAges, ImageView<const glm::vec2> prevLinearZ,
                ImageView<const uint32_t> prevMeshId, ImageView<uint32_t> ages) {
    const uint32_t width = cur.linearZ.width, height = cur.linearZ.height;
    const float w = float(width), h = float(height);
    for (uint32_t y = 0; y < height; ++y) {
        for (uint32_t x = 0; x < width; ++x) {
            uint32_t age = 0;
            const glm::vec2 z = cur.linearZ.at(x, y);
            const glm::vec2 mv = cur.mvec.at(x, y);
            // The previous pixel centre is (uv + mvec) * size - 0.5 = p + mvec * size; the nearest pixel is taken.
            // NaN fails every comparison below, so a non-finite motion vector or depth gives age 0.
            const float qxf = std::floor(float(x) + mv.x * w + 0.5f), qyf = std::floor(float(y) + mv.y * h + 0.5f);
            if (z.x >= 0.f && qxf >= 0.f && qyf >= 0.f && qxf < w && qyf < h) {
                const uint32_t qx = uint32_t(qxf), qy = uint32_t(qyf);
                const float zPrev = prevLinearZ.at(qx, qy).x;
                if (zPrev >= 0.f && prevMeshId.at(qx, qy) == cur.meshId.at(x, y) &&
                    std::abs(z.x - zPrev) <= kAgeDepthTolerance * z.x + z.y)
                    age = std::min(prevAges.at(qx, qy), kAgeCap - 1) + 1;
            }
            ages.at(x, y) = age;
        }
    }
}

std::optional<double> AgeBuckets::mean(uint32_t bucket) const {
    if (bucket > kAgeCap || count[bucket] == 0) return std::nullopt;
    return sum[bucket] / double(count[bucket]);
}

void addAgeErrors(ImageView<const uint32_t> ages, ImageView<const glm::vec2> linearZ, ImageView<const float> error,
                  ImageView<const glm::vec4> test, ImageView<const glm::vec4> ref, AgeBuckets& buckets) {
    for (uint32_t y = 0; y < ages.height; ++y) {
        for (uint32_t x = 0; x < ages.width; ++x) {
            if (!(linearZ.at(x, y).x >= 0.f) || !finiteRgb(test.at(x, y)) || !finiteRgb(ref.at(x, y))) continue;
            const uint32_t b = std::min(ages.at(x, y), kAgeCap);
            buckets.sum[b] += double(error.at(x, y));
            ++buckets.count[b];
        }
    }
}

std::optional<uint32_t> agesToRecover(const AgeBuckets& buckets, double tolerance) {
    const std::optional<double> steady = buckets.mean(kAgeCap);
    if (!steady) return std::nullopt;
    const double bound = (1.0 + tolerance) * *steady;
    // Walk down from the oldest bucket; the answer is one past the youngest bucket above the bound.
    for (uint32_t a = kAgeCap; a-- > 0;) {
        const std::optional<double> m = buckets.mean(a);
        if (m && *m > bound) return a + 1;
    }
    return 0u;
}

void DisocclusionTracker::addFrame(const AgeGBuffer& gbuffer, const Texture& test, const Texture& ref, bool cut,
                                   bool measured) {
    const uint32_t width = gbuffer.linearZ.width, height = gbuffer.linearZ.height;
    if (test.width() != width || test.height() != height) return;  // a measured field of another size: no ages
    if (mAges.width() != width || mAges.height() != height) {
        mAges = Texture(width, height, Format::R32U);
        mPrevAges = Texture(width, height, Format::R32U);
        mPrevLinearZ = Texture(width, height, Format::RG32F);
        mPrevMeshId = Texture(width, height, Format::R32U);
        mError = Texture(width, height, Format::R32F);
        cut = true;
    }
    std::swap(mAges, mPrevAges);
    if (cut)
        mAges.clear();
    else
        updateAges(gbuffer, constView(mPrevAges.view<uint32_t>()), constView(mPrevLinearZ.view<glm::vec2>()),
                   constView(mPrevMeshId.view<uint32_t>()), mAges.view<uint32_t>());
    if (measured) {
        relMSE(test, ref, &mError);
        addAgeErrors(constView(mAges.view<uint32_t>()), gbuffer.linearZ, constView(mError.view<float>()),
                     test.view<glm::vec4>(), ref.view<glm::vec4>(), mBuckets);
    }
    // This frame's guides for the next frame's test (the graph's own fields are reused or ping-ponged).
    for (uint32_t y = 0; y < height; ++y) {
        std::copy_n(gbuffer.linearZ.row(y), width, mPrevLinearZ.view<glm::vec2>().row(y));
        std::copy_n(gbuffer.meshId.row(y), width, mPrevMeshId.view<uint32_t>().row(y));
    }
}

std::vector<std::string> ageGBufferFields(const RenderGraph& graph) {
    const auto outputs = [](const Reflection& r, const char* name) {
        const FieldDesc* f = r.find(name);
        return f && f->kind == FieldKind::Output;
    };
    for (const std::string& name : graph.plan().order) {
        const RenderPass* pass = graph.pass(name);
        if (!pass) continue;
        Reflection r;
        pass->reflect(r, CompileInfo{});  // unwired: every field the pass can declare
        if (outputs(r, kLinearZ) && outputs(r, kMvec) && outputs(r, kMeshId))
            return {name + "." + kLinearZ, name + "." + kMvec, name + "." + kMeshId};
    }
    return {};
}

std::optional<AgeGBuffer> ageGBuffer(const RenderGraph& graph, const std::vector<std::string>& fields) {
    if (fields.size() != 3) return std::nullopt;
    const Texture* z = graph.fieldTexture(fields[0]);
    const Texture* mv = graph.fieldTexture(fields[1]);
    const Texture* mesh = graph.fieldTexture(fields[2]);
    if (!z || !mv || !mesh || z->format() != Format::RG32F || mv->format() != Format::RG32F ||
        mesh->format() != Format::R32U)
        return std::nullopt;
    if (mv->width() != z->width() || mv->height() != z->height() || mesh->width() != z->width() ||
        mesh->height() != z->height())
        return std::nullopt;
    return AgeGBuffer{z->view<glm::vec2>(), mv->view<glm::vec2>(), mesh->view<uint32_t>()};
}

Lag runLag(const std::vector<double>& relMSE, uint64_t firstFrame, const std::vector<uint32_t>& events,
           const DisocclusionTracker* ages) {
    Lag lag;
    lag.recoveries = frameRecoveries(relMSE, firstFrame, events);
    if (ages) {
        lag.ages = ages->buckets();
        lag.agesToRecover = agesToRecover(*lag.ages);
    }
    return lag;
}

namespace {

std::string ageLabel(uint32_t a) {
    return a < kAgeCap ? std::to_string(a) : std::to_string(kAgeCap) + "+";
}

std::string framesText(const Recovery& r) {
    if (!r.settled) return "not settled";
    return r.frames ? std::to_string(*r.frames) : std::string("not recovered");
}

}  // namespace

nlohmann::json lagJson(const Lag& lag) {
    auto optional = [](const auto& v) { return v ? nlohmann::json(*v) : nlohmann::json(); };
    nlohmann::json events = nlohmann::json::array();
    for (const Recovery& r : lag.recoveries)
        events.push_back({{"frame", r.frame},
                          {"kind", r.kind},
                          {"frames_to_recover", optional(r.frames)},
                          {"settled", r.settled},
                          {"steady_relmse", r.steady},
                          {"segment_frames", r.segmentFrames}});
    nlohmann::json j = {{"metric", "relmse"},
                        {"tolerance", kLagTolerance},
                        {"window", kLagWindow},
                        {"events", std::move(events)},
                        {"disocclusion", nullptr}};
    if (lag.ages) {
        nlohmann::json buckets = nlohmann::json::array();
        for (uint32_t a = 0; a <= kAgeCap; ++a)
            buckets.push_back({{"age", a},
                               {"label", ageLabel(a)},
                               {"relmse", optional(lag.ages->mean(a))},
                               {"samples", lag.ages->count[a]}});
        j["disocclusion"] = {{"age_cap", kAgeCap},
                             {"depth_tolerance", kAgeDepthTolerance},
                             {"buckets", std::move(buckets)},
                             {"frames_to_recover", optional(lag.agesToRecover)}};
    }
    return j;
}

std::string lagMarkdown(const std::vector<std::pair<std::string, const Lag*>>& runs) {
    std::ostringstream s;
    s << fmt::format(
        "Lag: frames until the RelMSE is back, for good, within {:.0f} % of its steady state (mean of {}-frame "
        "windows less their largest frame; docs/BENCH.md, \"Lag\"). Disocclusion: the smallest age (frames "
        "since a pixel became visible) from which the RelMSE of pixels of that age stays within {:.0f} % of the {}+ "
        "pixels'.\n\n",
        100 * kLagTolerance, kLagWindow, 100 * kLagTolerance, kAgeCap);
    s << "| graph | params | camera cut | lighting steps | disocclusion |\n|---|---|---:|---|---:|\n";
    bool anyAges = false;
    for (const auto& [label, lag] : runs) {
        std::string cut = "—", steps;
        for (const Recovery& r : lag->recoveries) {
            if (r.kind == "cut")
                cut = framesText(r);
            else
                steps += (steps.empty() ? "" : ", ") + fmt::format("{}: {}", r.frame, framesText(r));
        }
        const std::string ages =
            !lag->ages ? "—" : (lag->agesToRecover ? ageLabel(*lag->agesToRecover) : std::string("n/a"));
        anyAges = anyAges || lag->ages.has_value();
        s << fmt::format("{} | {} | {} | {} |\n", label, cut, steps.empty() ? "—" : steps, ages);
    }
    if (anyAges) {
        s << "\nRelMSE by age (frames since the pixel became visible; measured frames, pixels with a hit):\n\n";
        s << "| graph | params |";
        for (uint32_t a = 0; a <= kAgeCap; ++a) s << " " << ageLabel(a) << " |";
        s << "\n|---|---|";
        for (uint32_t a = 0; a <= kAgeCap; ++a) s << "---:|";
        s << "\n";
        for (const auto& [label, lag] : runs) {
            if (!lag->ages) continue;
            s << label << " |";
            for (uint32_t a = 0; a <= kAgeCap; ++a) {
                const std::optional<double> m = lag->ages->mean(a);
                s << " " << (m ? fmt::format("{:.4g}", *m) : std::string("—")) << " |";
            }
            s << "\n";
        }
    }
    s << "\n";
    return s.str();
}

}  // namespace loom::cli::bench
