#include "PathTracer.h"

#include <spdlog/spdlog.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <vector>

#include "CudaBackend.h"
#include "PathTracerKernels.h"
#include "PixelKernel.h"
#include "ShadeSimd.h"
#include "loom/Bvh.h"
#include "loom/CameraKernels.h"
#include "loom/CameraRays.h"
#include "loom/Channels.h"
#include "loom/Device.h"
#include "loom/EmbreeRays.h"
#include "loom/Error.h"
#include "loom/Launch.h"
#include "loom/Parallel.h"
#include "loom/RayScene.h"
#include "loom/Scene.h"

namespace loom {

namespace {
using channel::kAlbedo;
using channel::kColor;
using channel::kDirect;
using channel::kEmission;
using channel::kGradient;
using channel::kGradientBlock;
using channel::kIndirect;
using channel::kSpecAlbedo;
using channel::kVBuffer;
// History of the temporal gradients: the primary hit and luminance of each 3x3 block's sample of the frame.
const char kGradientHits[] = "gradientHits";
const char kGradientLuminance[] = "gradientLuminance";

using pt::gradientPixel;
static_assert(kGradientBlock == 3, "pt::gradientPixel's blocks are 3x3");

/// Rec. 709 luminance, what the temporal gradients compare.
float gradientLuminance(glm::vec3 c) {
    return luminance(c);
}

using pt::kPixelSampleKey;
using pt::PixelSum;

/// Paths of one tile kept in flight together (see execute()).
constexpr uint32_t kPathBatch = 256;

/// Per-thread scratch of a tile: its primary hits and one batch of paths with their rays.
struct TileScratch {
    std::vector<RayHit> primary;
    std::vector<glm::vec3> dir;
    std::vector<pt::PathState> paths;
    std::vector<RayHit> hits;
    std::vector<uint32_t> live, shadow;  // indices into paths: live paths, paths with a shadow ray
    std::vector<uint32_t> requests;      // per live path: what its shading asked to trace
    std::vector<RTCRay> shadowRays;
    std::vector<RTCRayHit> nextRays;
    void resize(uint32_t pixels) {
        if (primary.size() < pixels) {
            primary.resize(pixels);
            dir.resize(pixels);
        }
        if (paths.empty()) {
            paths.resize(kPathBatch);
            hits.resize(kPathBatch);
            live.resize(kPathBatch);
            shadow.resize(kPathBatch);
            requests.resize(kPathBatch);
            shadowRays.resize(kPathBatch);
            nextRays.resize(kPathBatch);
        }
    }
};

TileScratch& tileScratch() {
    thread_local TileScratch scratch;
    return scratch;
}

/// How bounce and shadow rays are traced: alpha-tested like every ray (when the pass's alphaTest is on), never
/// culled. Back-face culling is for camera rays only, as in rasterization; a single-sided wall still blocks
/// light and reflects from behind, so closed scenes stay closed. Coverage keys (rayCoverageKey) are computed only
/// where some geometry is alpha-tested: opaque scenes pay nothing for them.
struct SecondaryRays {
    RTCScene scene;
    const SceneView* view;
    uint32_t rules;  // RayRules
    bool keyed;      // coverage keys needed
    uint32_t key(glm::vec3 o, glm::vec3 d) const { return keyed ? rayCoverageKey(o, d) : 0u; }
    void initContext(HitFilterContext& ctx) const { initHitFilterContext(ctx, *view, rules); }
};

/// Traces the pending shadow rays of paths ts.shadow[0, n) as one Embree stream of incoherent rays and resolves
/// them into their paths (the same rays and tests as RayScene::occluded).
void traceShadowRays(const SecondaryRays& sr, TileScratch& ts, uint32_t n) {
    if (n == 0) return;
    for (uint32_t j = 0; j < n; ++j) {
        const pt::PathState& st = ts.paths[ts.shadow[j]];
        setStreamRay(ts.shadowRays[j], st.rayOrigin, st.shadowDir, st.shadowTMax, sr.key(st.rayOrigin, st.shadowDir));
    }
    HitFilterContext ctx;
    sr.initContext(ctx);
    rtcOccluded1M(sr.scene, &ctx.embree, ts.shadowRays.data(), n, sizeof(RTCRay));
    for (uint32_t j = 0; j < n; ++j)
        pt::resolveShadowRay(ts.paths[ts.shadow[j]], ts.shadowRays[j].tfar < 0.f);  // tfar = -inf: blocked
}

/// Traces the continuation rays of paths ts.live[0, n) as one incoherent Embree stream; hits go to ts.hits (the
/// same rays and hits as RayScene::intersect).
void traceNextRays(const SecondaryRays& sr, TileScratch& ts, uint32_t n) {
    if (n == 0) return;
    for (uint32_t j = 0; j < n; ++j) {
        const pt::PathState& st = ts.paths[ts.live[j]];
        RTCRayHit& rh = ts.nextRays[j];
        setStreamRay(rh.ray, st.rayOrigin, st.rayDir, 1e30f, sr.key(st.rayOrigin, st.rayDir));
        rh.hit.geomID = RTC_INVALID_GEOMETRY_ID;
        rh.hit.instID[0] = RTC_INVALID_GEOMETRY_ID;
    }
    HitFilterContext ctx;
    sr.initContext(ctx);
    rtcIntersect1M(sr.scene, &ctx.embree, ts.nextRays.data(), n, sizeof(RTCRayHit));
    for (uint32_t j = 0; j < n; ++j) {
        const RTCRayHit& rh = ts.nextRays[j];
        RayHit h;
        if (rh.hit.geomID != RTC_INVALID_GEOMETRY_ID) {
            h.instance = rh.hit.instID[0];
            h.primitive = rh.hit.primID;
            h.u = rh.hit.u;
            h.v = rh.hit.v;
            h.t = rh.ray.tfar;
        }
        ts.hits[ts.live[j]] = h;
    }
}
/// What every batch of paths shares.
struct BatchContext {
    const SecondaryRays& secondary;
    const SceneView& view;
    const pt::LightsView& lights;
    const pt::PathTracerSettings& set;
    bool simd;
    uint32_t lanes;
    uint32_t features;  // pt::KernelFeature bits of the kernel the scene needs (pt::kAllFeatures: the generic one)
    bool skipIdle;      // skip the vector shading of batches whose paths all ended (specialize)
};

/// Shades the live paths ts.live[0, live) with the SIMD kernel compiled for feature bits F. The per-path kernel (a
/// validation mode) is always the generic one: compiled inline into this loop, a variant of it may fuse multiplies
/// and adds differently (GCC contracts across what inlining exposes), and the skip must not change a bit.
template <uint32_t F>
void shadeLive(const BatchContext& b, TileScratch& ts, uint32_t live) {
    if (b.simd) {
        for (uint32_t j = 0; j < live; j += b.lanes)
            pt::shadeVerticesSimd<F>(ts.paths.data(), ts.hits.data(), &ts.live[j], std::min(b.lanes, live - j), b.view,
                                     b.lights, b.set, &ts.requests[j], b.skipIdle);
    } else {
        for (uint32_t j = 0; j < live; ++j) {
            const uint32_t k = ts.live[j];
            ts.requests[j] = pt::shadeVertex(ts.paths[k], ts.hits[k], b.view, b.lights, b.set);
        }
    }
}

/// Runs paths ts.paths[0, count) (begun, their first hits in ts.hits) to their ends as a small wavefront: each round
/// shades every live path, then traces all their shadow rays as one Embree stream, then all their continuation rays
/// as another.
void runPaths(const BatchContext& b, TileScratch& ts, uint32_t count) {
    for (uint32_t k = 0; k < count; ++k) ts.live[k] = k;
    uint32_t live = count;
    while (live > 0) {
        // Two kernels: the generic one, and one without any optional feature (the smallest superset of a scene's
        // needs among them; see PathTracer::kernelFeatures()).
        if (b.features == 0u)
            shadeLive<0u>(b, ts, live);
        else
            shadeLive<pt::kAllFeatures>(b, ts, live);
        uint32_t shadows = 0, next = 0;
        for (uint32_t j = 0; j < live; ++j) {
            const uint32_t k = ts.live[j];
            const uint32_t request = ts.requests[j];
            ts.shadow[shadows] = k;
            shadows += (request & pt::kShadowRay) ? 1u : 0u;
            ts.live[next] = k;
            next += (request & pt::kNextRay) ? 1u : 0u;
        }
        traceShadowRays(b.secondary, ts, shadows);
        traceNextRays(b.secondary, ts, next);
        live = next;
    }
}

/// Sums a pixel's samples as the colour output does: in sample order, in double, non-finite samples dropped.
}  // namespace

void PathTracer::reflect(Reflection& r, const CompileInfo& info) const {
    r.input(kVBuffer, Format::RGBA32U).optional().doc("primary hits from a G-buffer (else camera rays)");
    r.output(kColor, Format::RGBA32F).doc("path-traced radiance, mean over samplesPerPixel");
    r.output(kAlbedo, Format::RGBA32F).optional().doc("diffuse reflectance at the primary hit");
    r.output(kSpecAlbedo, Format::RGBA32F).optional().doc("directional specular reflectance at the primary hit");
    r.output(kEmission, Format::RGBA32F).optional().doc("emitted radiance at the primary hit");
    r.output(kDirect, Format::RGBA32F).optional().doc("direct lighting part of color");
    r.output(kIndirect, Format::RGBA32F).optional().doc("indirect lighting part of color");
    r.output(kGradient, Format::RG32F)
        .optional()
        .doc(
            "temporal gradients (A-SVGF), on last frame's pixel grid: for one pixel of each 3x3 block, (luminance of "
            "its samples re-shaded this frame at the same surface points with the same random numbers, their "
            "luminance last frame), replicated over the block; (0, 0) without history, on a miss or with pixelFilter "
            "box. Equal where the shading did not change");
    if (!info.wired || info.isOutputConsumed(kGradient)) {
        r.history(kGradientHits, Format::RGBA32U)
            .perBlock(kGradientBlock, kGradientBlock)
            .doc(
                "primary hit (instance, primitive, u and v bits) of each 3x3 block's gradient sample, one texel a "
                "block (gradient only)");
        r.history(kGradientLuminance, Format::R32F)
            .perBlock(kGradientBlock, kGradientBlock)
            .doc("colour luminance of each 3x3 block's gradient sample, one texel a block (gradient only)");
    }
}

void PathTracer::declareParams(ParamList& p) {
    const pt::PathTracerSettings defaults;
    p.add("maxBounces", &mSettings.maxBounces, defaults.maxBounces)
        .range(0, 64)
        .role(ParamRole::MaxBounces)
        .doc("scattering events per path (0: emission seen directly)");
    p.add("samplesPerPixel", &mSamplesPerPixel, 1)
        .range(1, 4096)
        .role(ParamRole::SampleCount)
        .doc("paths per pixel per frame");
    p.add("rrStartBounce", &mSettings.rrStartBounce, defaults.rrStartBounce)
        .range(0, 64)
        .role(ParamRole::RussianRouletteStart)
        .doc("Russian roulette from this bounce on");
    p.addEnum("lightSampling", &mSettings.lightSampling, defaults.lightSampling, {"mis", "nee", "bsdf"})
        .doc("direct light by MIS of light and BRDF sampling, light sampling only, or BRDF sampling only");
    p.add("lambertOnly", &mSettings.lambertOnly, defaults.lambertOnly)
        .doc("replace the glTF BRDF by baseColor/pi (validation)");
    p.add("gradientFromCurrentView", &mSettings.gradientFromCurrentView, defaults.gradientFromCurrentView)
        .doc(
            "temporal gradients re-shade last frame's sample from this frame's camera position (A-SVGF), so shading "
            "that depends on the view (highlights) shows as a change; false: along last frame's camera ray, equal "
            "bit for bit where only the camera moved");
    p.add("indirectClamp", &mSettings.indirectClamp, defaults.indirectClamp)
        .range(0.f, 1e6f)
        .doc(
            "firefly guard: the largest channel of any contribution after the first bounce is clamped to this "
            "(biased, darker); 0 = off, as references need");
    p.add("energyCompensation", &mSettings.multiScatter, defaults.multiScatter)
        .doc(
            "multiple-scattering energy compensation of the glTF BRDF (a white furnace reflects 1 at every "
            "roughness and view); false: glTF 2.0 Appendix B exactly, single scattering");
    p.addEnum("device", &mDevice, Device::Auto, {"auto", "cpu", "cuda", "emulated"})
        .doc(
            "where to run: auto = the CUDA backend where a usable NVIDIA GPU is present, else the CPU (the log says "
            "which, once); cpu = Embree on the CPU threads; cuda = the CUDA backend, an error without a usable "
            "device; emulated = the CUDA backend's kernels (BVH traversal, one path per pixel and sample) run on "
            "the CPU threads, to validate them (slower than cpu; the image agrees with cpu's where both traversals "
            "find the same hits)");
    p.add("seed", &mSeed, 0).range(0, 1 << 30).role(ParamRole::Seed).doc("decorrelates runs that share frame indices");
    p.addEnum("emissionWeights", &mEmissionWeights, EmissionWeights::Texture, {"texture", "area"})
        .doc(
            "light selection: emissive triangles by area times their emission's mean over the triangle (an emissive "
            "texture's footprint included; black ones are no lights), or by area times the emissive factor alone "
            "(ignores the texture, for comparison)");
    p.add("simdShading", &mSimdShading, true)
        .doc(
            "CPU: shade several paths at once in SIMD lanes (MIS with the glTF BRDF; other modes always run per "
            "path); false runs the per-path kernel, for comparison");
    p.addEnum("cullMode", &mCullMode, CullMode::Back, {"none", "back"})
        .doc(
            "camera rays skip back faces of single-sided materials, as the G-buffers' cullMode (bounce and shadow "
            "rays never cull)");
    p.addEnum("pixelFilter", &mPixelFilter, PixelFilter::Center, {kPixelFilterCenter, kPixelFilterBox})
        .role(ParamRole::PixelFilter)
        .doc(
            "where camera paths start in the pixel: center = every sample at the (jittered) pixel centre, as the "
            "G-buffers see it; box = each sample uniformly in the pixel, camera jitter ignored (an anti-aliased "
            "image, for references of jittered sequences; its own camera rays, so a vbuffer feeds only albedo, "
            "specAlbedo and emission)");
    p.add("specialize", &mSpecialize, true)
        .doc(
            "skip what the scene does not need (skippedWork lists it): a kernel without textured-emitter and "
            "environment-map code where the scene has neither, no vector shading of batches of ended paths, and "
            "for a static scene the light list built once; the image is the same bit for bit. false: the generic "
            "kernel and per-frame rebuilds, for comparison");
    p.add("alphaTest", &mAlphaTest, true)
        .doc(
            "every ray: alphaMode MASK passes where alpha < alphaCutoff, BLEND is stochastic transparency (there "
            "with probability alpha, as in the G-buffers); false: every material opaque");
}

bool PathTracer::runsOn(DeviceKind device) const {
    // The CUDA backend's kernels run on any device: on emulated over the CPU threads, on cuda where the build has
    // the backend (nvcc).
    return device != DeviceKind::Cuda || pt::CudaBackend::compiled();
}

void PathTracer::compile(const CompileInfo&) {
    // Where the graph places the pass decides where frames run (execute, ctx.device()). `device` chooses the
    // backend only when the pass is placed on the CPU: auto and cpu are Embree there, cuda and emulated the CUDA
    // backend's kernels (on the GPU, copied back into the host fields; or on the CPU threads).
    switch (mDevice) {
        case Device::Auto:
        case Device::Cpu:
            mActive = Backend::Cpu;
            return;
        case Device::Emulated:
            mActive = Backend::Emulated;
            return;
        case Device::Cuda:
            break;
    }
    const CudaStatus& cuda = cudaStatus();
    if (!cuda.usable)
        throwBadInput("PathTracer.device", "device 'cuda' was asked for, and " + cuda.description,
                      "a usable NVIDIA GPU with its driver, in a build with the CUDA backend",
                      "set device to auto (where the graph places the pass: `--device`) or cpu");
    mActive = Backend::Cuda;
    if (!mCuda) mCuda = std::make_unique<pt::CudaBackend>();
    // Said once per process, not once per pass or frame.
    static std::atomic<bool> reported{false};
    if (!reported.exchange(true)) spdlog::info("PathTracer: running on the CUDA device {}", cuda.description);
}

PathTracer::PathTracer() = default;
PathTracer::~PathTracer() = default;


void PathTracer::setScene(const std::shared_ptr<const Scene>& scene) {
    mScene = scene;
    mEnvSource = nullptr;
    mEmissionSource = nullptr;
    mLightsSource = nullptr;
}

uint32_t PathTracer::kernelFeatures() const {
    if (!mSpecialize) return pt::kAllFeatures;
    const uint32_t f = (mLights.env.texels ? pt::kEnvironmentMap : 0u) | (mEmitterSurfaces ? pt::kEmitterSurfaces : 0u);
    // Only two kernels are compiled: none of the features, or all of them.
    return f == 0u ? 0u : pt::kAllFeatures;
}

std::vector<std::string> PathTracer::skippedWork() const {
    std::vector<std::string> lines;
    // The scene's features decide most of it; the kernel chosen and the shading path need a frame (loom check asks
    // before the first one).
    const Scene* scene = mLightsSource ? static_cast<const Scene*>(mLightsSource) : mScene.get();
    if (!mSpecialize || !scene) return lines;
    const SceneFeatures& f = scene->features();
    const bool rendered = mLightsSource != nullptr;
    if (rendered && mKernelFeatures == 0u)
        lines.push_back("emitter material at light samples: no emissive texture or alpha-tested emitter");
    if (f.environment != EnvironmentKind::Map && (!rendered || mKernelFeatures == 0u))
        lines.push_back("environment map lookups: the environment is " +
                        std::string(f.environment == EnvironmentKind::None ? "black" : "a constant colour"));
    if (rendered && mSimdUsed)
        lines.push_back("vector shading of batches of ended paths: misses end at the primary ray");
    if (!f.animatedNodes && !f.animatedLights)
        lines.push_back("per-frame light list: nothing moves and no emission is animated (built once)");
    else if (!f.animatedLights)
        lines.push_back("light list rebuilds while no instance moves: no emission is animated");
    if (!f.emissiveTriangles) lines.push_back("emissive-triangle sampling: the scene has no emissive triangles");
    if (!f.punctualLights) lines.push_back("punctual-light sampling: the scene has no punctual light");
    if (f.environment == EnvironmentKind::None) lines.push_back("environment sampling: the environment is black");
    return lines;
}

void PathTracer::buildEnvironment(const Scene& scene) {
    const Environment& env = scene.environment;
    pt::EnvView& v = mLights.env;
    v = pt::EnvView{};
    v.color = env.color;
    v.intensity = env.intensity;
    mEnvMarginal.clear();
    mEnvConditional.clear();
    if (!env.isConstant()) {
        v.texels = env.texels.data();
        v.width = env.width;
        v.height = env.height;
        // Piecewise-constant 2D distribution over texels, weight = luminance * sin(theta)
        // (pbrt-v3, 13.6.7, "Piecewise-Constant 2D Distributions").
        mEnvConditional.resize(size_t(env.height) * (env.width + 1));
        mEnvMarginal.resize(env.height + 1);
        double total = 0.0;
        std::vector<double> rowSums(env.height);
        for (uint32_t y = 0; y < env.height; ++y) {
            const double sinTheta = std::sin((y + 0.5) / env.height * pt::kPi);
            double acc = 0.0;
            float* row = &mEnvConditional[size_t(y) * (env.width + 1)];
            row[0] = 0.f;
            for (uint32_t x = 0; x < env.width; ++x) {
                acc += double(luminance(env.texels[size_t(y) * env.width + x])) * sinTheta;
                row[x + 1] = float(acc);
            }
            for (uint32_t x = 1; x <= env.width; ++x)
                row[x] = acc > 0.0 ? float(row[x] / acc) : float(x) / float(env.width);
            row[env.width] = 1.f;
            rowSums[y] = acc;
            total += acc;
        }
        mEnvMarginal[0] = 0.f;
        double acc = 0.0;
        for (uint32_t y = 0; y < env.height; ++y) {
            acc += rowSums[y];
            mEnvMarginal[y + 1] = total > 0.0 ? float(acc / total) : float(y + 1) / float(env.height);
        }
        mEnvMarginal[env.height] = 1.f;
        v.marginalCdf = mEnvMarginal.data();
        v.conditionalCdf = mEnvConditional.data();
        v.weightSum = float(total);
        mLights.hasEnv = total > 0.0;
    } else {
        mLights.hasEnv = luminance(env.color * env.intensity) > 0.f;
    }
    mEnvSource = &scene;
}

/// Subdivisions per texel along a triangle's longest edge in its emissive texture when its mean emission is measured:
/// every sub-triangle (one sample point each) then spans at most a quarter texel along each of its edges, so the
/// bilinear filter's variation is resolved and a triangle over black texels reads exactly 0.
constexpr double kEmissionSubdivisionsPerTexel = 4.0;
/// A triangle's mean is measured at m * m points, m from 3 (triangles under a texel) to 64 (4096 points).
constexpr uint32_t kEmissionMinSubdivision = 3, kEmissionMaxSubdivision = 64;
/// Most surface evaluations one mesh's means may cost, once per scene (2^20: 0.12-0.15 s on two busy cores); beyond
/// it every triangle's subdivision shrinks in proportion (at least its centroid is evaluated).
constexpr double kEmissionMeshBudget = double(1u << 20);
/// Weight, per unit area and relative to the emissive factor's luminance, of a triangle whose points all read black
/// although they were sparser than kEmissionSubdivisionsPerTexel asks (the budget or the subdivision cap): a few bright
/// texels may lie between them, so it stays a (dim) light and light sampling still reaches it.
constexpr float kUnresolvedEmissionWeight = 1e-3f;

const std::vector<float>& PathTracer::triangleEmission(const Scene& scene, uint32_t instance) {
    if (mEmissionSource != &scene) {
        mTriEmission.assign(scene.meshes.size(), {});
        mTriEmissionFactor.assign(scene.meshes.size(), glm::vec3(0.f));
        mEmissionSource = &scene;
    }
    const uint32_t meshIndex = scene.instances[instance].mesh;
    std::vector<float>& means = mTriEmission[meshIndex];
    const Mesh& mesh = scene.meshes[meshIndex];
    const uint32_t n = mesh.triangleCount();
    const Material& mat = scene.materials[mesh.material];
    // The means include the emissive factor, which an animation may change: measured again when it did.
    if (means.size() == n && mTriEmissionFactor[meshIndex] == mat.emissiveFactor) return means;
    mTriEmissionFactor[meshIndex] = mat.emissiveFactor;
    const SceneImage& image = scene.images[size_t(mat.emissiveTexture.image)];
    // Subdivision each triangle needs for its texel footprint (its longest uv edge in texels), and what the caps allow.
    const glm::dvec2 size(image.width, image.height);
    std::vector<uint32_t> needed(n), used(n);
    double total = 0.0;
    for (uint32_t t = 0; t < n; ++t) {
        const glm::dvec2 uv0 = mesh.uvs[mesh.indices[3 * t]], uv1 = mesh.uvs[mesh.indices[3 * t + 1]],
                         uv2 = mesh.uvs[mesh.indices[3 * t + 2]];
        const double edge = std::max(
            {glm::length((uv1 - uv0) * size), glm::length((uv2 - uv1) * size), glm::length((uv0 - uv2) * size)});
        const double m = std::isfinite(edge) ? std::ceil(kEmissionSubdivisionsPerTexel * edge) : 1e6;
        needed[t] = uint32_t(std::clamp(m, double(kEmissionMinSubdivision), 1e6));
        used[t] = std::min(needed[t], kEmissionMaxSubdivision);
        total += double(used[t]) * used[t];
    }
    if (total > kEmissionMeshBudget) {
        const double shrink = std::sqrt(kEmissionMeshBudget / total);
        for (uint32_t& m : used) m = std::max(1u, uint32_t(double(m) * shrink));
    }
    means.resize(n);
    const SceneView& view = scene.view();
    const float unresolved = kUnresolvedEmissionWeight * luminance(mat.emissiveFactor);
    // Triangles are independent: the means do not depend on the thread count.
    parallelFor2D(
        n, 1,
        [&](const Tile& tile) {
            for (uint32_t t = tile.x0; t < tile.x1; ++t) {
                const float mean = pt::meanEmittedLuminance(view, instance, t, used[t]);
                means[t] = mean > 0.f || used[t] >= needed[t] ? mean : unresolved;
            }
        },
        64, 1);
    return means;
}

void PathTracer::buildLights(const Scene& scene) {
    mTris.clear();
    mInstanceTriBase.assign(scene.instances.size(), 0xFFFFFFFFu);
    for (uint32_t i = 0; i < scene.instances.size(); ++i) {
        const Instance& inst = scene.instances[i];
        const Mesh& mesh = scene.meshes[inst.mesh];
        const Material& mat = scene.materials[mesh.material];
        if (!mat.isEmissive() || !inst.visible()) continue;
        mInstanceTriBase[i] = uint32_t(mTris.size());
        // Selection weight: area times the mean emitted luminance over the triangle. A textured emitter's mean is
        // its own (a triangle over black texels is no light); the "area" weighting ignores the texture.
        const bool textured = mat.emissiveTexture.image >= 0;
        const bool perTriangle = textured && mEmissionWeights == EmissionWeights::Texture;
        const std::vector<float>* means = perTriangle ? &triangleEmission(scene, i) : nullptr;
        const float lum = luminance(mat.emissiveFactor);
        for (uint32_t t = 0; t < mesh.triangleCount(); ++t) {
            const glm::vec3 a = glm::vec3(inst.world * glm::vec4(mesh.positions[mesh.indices[3 * t]], 1.f));
            const glm::vec3 b = glm::vec3(inst.world * glm::vec4(mesh.positions[mesh.indices[3 * t + 1]], 1.f));
            const glm::vec3 c = glm::vec3(inst.world * glm::vec4(mesh.positions[mesh.indices[3 * t + 2]], 1.f));
            pt::EmissiveTri e;
            e.p0 = a;
            e.e1 = b - a;
            e.e2 = c - a;
            const glm::vec3 cr = glm::cross(e.e1, e.e2);
            const float len = glm::length(cr);
            e.area = 0.5f * len;
            e.normal = len > 0.f ? cr / len : glm::vec3(0.f, 1.f, 0.f);
            e.power = e.area > 0.f ? e.area * (means ? (*means)[t] : lum) : 0.f;
            e.instance = i;
            e.primitive = t;
            e.doubleSided = mat.doubleSided ? 1u : 0u;
            e.textured = textured ? 1u : 0u;
            e.alphaTested = mAlphaTest && mat.alphaMode != AlphaMode::Opaque ? 1u : 0u;
            e.radiance = mat.emissiveFactor;
            mTris.push_back(e);
        }
    }
    mEmitterSurfaces =
        std::any_of(mTris.begin(), mTris.end(), [](const pt::EmissiveTri& t) { return t.textured || t.alphaTested; });
    mTriCdf.assign(mTris.size() + 1, 0.f);
    const double total = pt::fillTriangleCdf(mTris.data(), uint32_t(mTris.size()), mTriCdf.data());

    mPunctual.clear();
    for (const Light& l : scene.lights) {
        pt::PunctualLight p;
        p.type = l.type == LightType::Point ? pt::kPoint : l.type == LightType::Spot ? pt::kSpot : pt::kDirectional;
        p.position = l.position;
        p.direction = glm::normalize(l.direction);
        p.intensity = l.color * l.intensity;
        p.cosInner = std::cos(l.innerConeAngle);
        p.cosOuter = std::cos(l.outerConeAngle);
        p.range = l.range;
        if (luminance(p.intensity) > 0.f) mPunctual.push_back(p);
    }

    pt::LightsView& L = mLights;
    L.tris = mTris.data();
    L.triCdf = mTriCdf.data();
    L.instanceTriBase = mInstanceTriBase.data();
    L.triCount = uint32_t(mTris.size());
    L.triPowerSum = float(total);
    L.punctual = mPunctual.data();
    L.punctualCount = uint32_t(mPunctual.size());
    // Each kind of light present gets an equal share of the samples.
    const float kinds = float((total > 0.0) + !mPunctual.empty() + L.hasEnv);
    L.pTris = total > 0.0 ? 1.f / kinds : 0.f;
    L.pPunctual = !mPunctual.empty() ? 1.f / kinds : 0.f;
    L.pEnv = L.hasEnv ? 1.f / kinds : 0.f;
    pt::setTrianglePdfs(mTris.data(), uint32_t(mTris.size()), mTriCdf.data(), L.pTris);
}

namespace {

/// A block's gradient sample: last frame's pixel and primary hit.
struct GradientSample {
    glm::uvec2 block, pixel;
    RayHit hit;
    glm::vec3 origin, dir;  ///< the ray it is re-shaded along (pt::gradientRay)
};

/// Writes a block's gradient value into each of its pixels.
void fillBlock(ImageView<glm::vec2> out, glm::uvec2 block, glm::vec2 value) {
    for (uint32_t y = block.y * kGradientBlock; y < std::min(out.height, (block.y + 1) * kGradientBlock); ++y)
        for (uint32_t x = block.x * kGradientBlock; x < std::min(out.width, (block.x + 1) * kGradientBlock); ++x)
            out.at(x, y) = value;
}

/// The temporal gradients (output `gradient`): last frame's gradient sample of every block re-shaded now, at the
/// same surface point (its hit follows animated instances) along last frame's camera ray with last frame's random
/// numbers, next to its luminance then. Where nothing changed both are the same. Returns the rays traced.
uint64_t traceGradients(PassContext& ctx, const BatchContext& batch, const Camera& camera, uint32_t spp, uint64_t frame,
                        ImageView<glm::vec2> out) {
    const uint32_t w = out.width, h = out.height;
    if (!ctx.historyValid() || ctx.frameIndex() == 0) {
        ctx.output(kGradient)->clear();
        return 0;
    }
    const auto prevHits = ctx.historyPrev(kGradientHits).view<glm::uvec4>();
    const auto prevLum = ctx.historyPrev(kGradientLuminance).view<float>();
    // Last frame's camera rays, exactly: its pose and jitter.
    Camera prev = camera;
    prev.world = camera.prevWorld;
    prev.jitter = camera.prevJitter;
    prev.aspect = float(w) / float(h);
    const CameraData prevCam = makeCameraData(prev, w, h);
    const SceneView& view = batch.view;
    const uint32_t blocksX = (w + kGradientBlock - 1) / kGradientBlock,
                   blocksY = (h + kGradientBlock - 1) / kGradientBlock;
    std::vector<uint64_t> tileRays;
    const uint32_t tileBlocks = 16;
    const uint32_t tilesX = (blocksX + tileBlocks - 1) / tileBlocks, tilesY = (blocksY + tileBlocks - 1) / tileBlocks;
    tileRays.assign(size_t(tilesX) * tilesY, 0);
    parallelFor2D(
        blocksX, blocksY,
        [&](const Tile& tile) {
            TileScratch& ts = tileScratch();
            ts.resize(1);
            uint64_t rays = 0;
            std::vector<GradientSample> samples;
            for (uint32_t by = tile.y0; by < tile.y1; ++by)
                for (uint32_t bx = tile.x0; bx < tile.x1; ++bx) {
                    const glm::uvec2 q = gradientPixel(bx, by, ctx.frameIndex() - 1, w, h);
                    const glm::uvec4 e = prevHits.at(bx, by);
                    const bool valid =
                        e.x < view.instanceCount && e.y < view.meshes[view.instances[e.x].mesh].triangleCount;
                    if (!valid) {
                        fillBlock(out, glm::uvec2(bx, by), glm::vec2(0.f));
                        continue;
                    }
                    RayHit hit;
                    hit.instance = e.x;
                    hit.primitive = e.y;
                    hit.u = bitsToFloat(e.z);
                    hit.v = bitsToFloat(e.w);
                    GradientSample g{glm::uvec2(bx, by), q, hit, {}, {}};
                    pt::gradientRay(view, batch.set, prevCam, camera.position(), q.x, q.y, hit, g.origin, g.dir);
                    samples.push_back(g);
                }
            // Paths sample-minor, as the colour's: each sample's sums in the same order give the same bits.
            const uint64_t total = uint64_t(samples.size()) * spp;
            PixelSum acc;
            uint32_t current = 0, seen = 0;
            for (uint64_t first = 0; first < total; first += kPathBatch) {
                const uint32_t count = uint32_t(std::min<uint64_t>(kPathBatch, total - first));
                for (uint32_t k = 0; k < count; ++k) {
                    const uint64_t item = first + k;
                    const GradientSample& g = samples[size_t(item / spp)];
                    const uint32_t s = uint32_t(item % spp);
                    pt::beginPath(ts.paths[k], g.origin, g.dir, pt::PathRng(g.pixel.y * w + g.pixel.x, frame - 1, s));
                    ts.hits[k] = g.hit;
                }
                runPaths(batch, ts, count);
                for (uint32_t k = 0; k < count; ++k) {
                    rays += ts.paths[k].r.rays;
                    acc.add(ts.paths[k].r);
                    if (++seen < spp) continue;
                    const GradientSample& g = samples[current++];
                    fillBlock(out, g.block,
                              glm::vec2(gradientLuminance(acc.color()), prevLum.at(g.block.x, g.block.y)));
                    acc = PixelSum{};
                    seen = 0;
                }
            }
            tileRays[size_t(tile.y0 / tileBlocks) * tilesX + tile.x0 / tileBlocks] = rays;
        },
        tileBlocks);
    uint64_t rays = 0;
    for (uint64_t r : tileRays) rays += r;
    ctx.stats().set("gradientSamples", double(uint64_t(blocksX) * blocksY));
    return rays;
}

/// The temporal gradients of a frame (on the CPU, for every backend): traced, or cleared where the samples kept are
/// not the ones the box filter drew. Returns the rays traced.
uint64_t gradients(PassContext& ctx, const BatchContext& batch, const Camera& camera, uint32_t spp, uint64_t frame,
                   Texture* gradientTex, bool boxFilter) {
    if (boxFilter) {
        gradientTex->clear();  // the samples stored are the centre filter's: no exact replay of box samples
        return 0;
    }
    return traceGradients(ctx, batch, camera, spp, frame, gradientTex->view<glm::vec2>());
}

/// A field's pixels for this frame's kernels: the host view placed on the CPU, else the device view (the pass's
/// fields then live in its device's memory, which only kernels launched there touch).
template <class T>
ImageView<T> fieldView(Texture& t, bool onDevice) {
    return onDevice ? t.deviceView<T>() : t.view<T>();
}
template <class T>
ImageView<const T> fieldView(const Texture& t, bool onDevice) {
    return onDevice ? t.deviceView<T>() : t.view<T>();
}

/// An image view as the CUDA backend's kernels write it (pitch in elements; rows of textures are whole elements).
template <class T>
pt::PixelOut<T> pixelOut(ImageView<T> v) {
    return {v.data, uint32_t(v.rowPitch / sizeof(T))};
}

/// The end of a frame on any backend: its stats.
void finishFrame(PassContext& ctx, uint32_t spp, uint64_t rays, uint64_t dropped,
                 const std::vector<pt::EmissiveTri>& tris, std::chrono::steady_clock::time_point start) {
    const uint32_t w = ctx.frameWidth(), h = ctx.frameHeight();
    ctx.stats().set("rays", double(rays));
    ctx.stats().set("paths", double(uint64_t(w) * h * spp));
    ctx.stats().set("nonFiniteSamplesDropped", double(dropped));
    ctx.stats().set("emissiveTriangles", double(tris.size()));
    ctx.stats().set("lightTriangles", double(std::count_if(tris.begin(), tris.end(),
                                                           [](const pt::EmissiveTri& t) { return t.pdfArea > 0.f; })));
    // Throughput of this frame (timing only; it never changes the image).
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (seconds > 0.0) ctx.stats().set("pathsPerSecond", double(uint64_t(w) * h * spp) / seconds);
}

}  // namespace

void PathTracer::execute(PassContext& ctx) {
    const auto start = std::chrono::steady_clock::now();
    const Scene* scene = ctx.scene();
    if (!scene || !ctx.camera())
        throwBadInput(ctx.passName(), "the path tracer needs a scene", "a scene given with --scene",
                      "render with `loom render --scene data/scenes/cornell_box.gltf ...`");
    if (mEnvSource != scene) buildEnvironment(*scene);
    // A static scene's lights never change: its light list is built once (specialize), else every frame (animated
    // instances and emission are followed).
    const SceneFeatures& features = scene->features();
    const bool lightsStatic = mSpecialize && !features.animatedLights;
    if (!lightsStatic || mLightsSource != scene || mLightsVersion != scene->geometryVersion() ||
        mLightsAlphaTest != mAlphaTest || mLightsWeights != mEmissionWeights) {
        buildLights(*scene);
        mLightsSource = scene;
        mLightsVersion = scene->geometryVersion();
        mLightsAlphaTest = mAlphaTest;
        mLightsWeights = mEmissionWeights;
    }

    const uint32_t w = ctx.frameWidth(), h = ctx.frameHeight();
    Camera camera = *ctx.camera();
    camera.aspect = float(w) / float(h);
    const CameraData cam = makeCameraData(camera, w, h);
    const SceneView& view = scene->view();
    const RayScene& rayScene = scene->rayScene();
    const uint32_t alphaRules = mAlphaTest ? kRayAlphaTest : 0u;
    const uint32_t cameraRules = alphaRules | (mCullMode == CullMode::Back ? kRayCullBackFaces : 0u);
    const SecondaryRays secondary{static_cast<RTCScene>(rayScene.embreeScene()), &view, alphaRules,
                                  mAlphaTest && rayScene.hasAlphaTestedGeometry()};
    const pt::PathTracerSettings set = mSettings;
    const bool boxFilter = mPixelFilter == PixelFilter::Box;
    const uint32_t spp = uint32_t(mSamplesPerPixel);
    // Seed s draws the random numbers of frames s * 2^32 + index: an index past 2^32 would repeat seed s + 1's.
    if (ctx.frameIndex() > 0xFFFFFFFFull)
        throw Error(Error::Info{ErrorKind::Runtime,
                                {},
                                ctx.passName(),
                                fmt::format("frame index {} is past 2^32 - 1, where seed {}'s random numbers would "
                                            "repeat those of seed {}",
                                            ctx.frameIndex(), mSeed, mSeed + 1),
                                "frame indices below 2^32",
                                "start again from a lower frame index"});
    const uint64_t frame = ctx.frameIndex() + (uint64_t(mSeed) << 32);
    const pt::LightsView lights = mLights;
    // Vertices are shaded several paths at a time in SIMD lanes where the settings allow (the default).
    const bool simd = mSimdShading && pt::simdShadingSupports(set);
    mKernelFeatures = simd ? kernelFeatures() : pt::kAllFeatures;
    mSimdUsed = simd;
    const uint32_t lanes = pt::shadeLanes();

    // Placed on a device (emulated, cuda), the fields are that device's memory: the kernels' views of it.
    const bool onDevice = ctx.device() != DeviceKind::Cpu;
    const Texture* vbTex = ctx.input(kVBuffer);
    const ImageView<const glm::uvec4> vbuffer =
        vbTex ? fieldView<glm::uvec4>(*vbTex, onDevice) : ImageView<const glm::uvec4>{};
    auto view4 = [&](const char* name) {
        Texture* t = ctx.output(name);
        return t ? fieldView<glm::vec4>(*t, onDevice) : ImageView<glm::vec4>{};
    };
    const ImageView<glm::vec4> color = view4(kColor), albedo = view4(kAlbedo), specAlbedo = view4(kSpecAlbedo),
                               emission = view4(kEmission), direct = view4(kDirect), indirect = view4(kIndirect);
    const bool wantsPrimary = albedo.data || specAlbedo.data || emission.data;
    const BatchContext batch{secondary, view, lights, set, simd, lanes, mKernelFeatures, mSpecialize};
    // Temporal gradients: this frame keeps one sample per block (hit, luminance) for the next one.
    Texture* gradientTex = ctx.output(kGradient);
    const ImageView<glm::uvec4> gradientHits =
        gradientTex ? fieldView<glm::uvec4>(ctx.historyCur(kGradientHits), onDevice) : ImageView<glm::uvec4>{};
    const ImageView<float> gradientLum =
        gradientTex ? fieldView<float>(ctx.historyCur(kGradientLuminance), onDevice) : ImageView<float>{};
    const bool split = direct.data || indirect.data;

    if (onDevice || mActive != Backend::Cpu) {
        // The CUDA backend's kernels (PixelKernel.h): on the device the graph placed the pass on, else (placed on
        // the CPU) where `device` asks for them.
        const Bvh& bvh = mBvh.update(*scene);
        pt::FrameKernel k;
        k.bvh = bvh.view(view);
        k.scene = view;
        k.lights = lights;
        k.set = set;
        k.cam = cam;
        k.width = w;
        k.height = h;
        k.spp = spp;
        k.frame = frame;
        k.coverageFrame = uint32_t(ctx.frameIndex());
        k.cameraRules = cameraRules;
        k.secondaryRules = alphaRules;
        k.keyed = secondary.keyed;
        k.boxFilter = boxFilter;
        if (vbuffer.data) {
            k.vbuffer = vbuffer.data;
            k.vbufferPitch = uint32_t(vbuffer.rowPitch / sizeof(glm::uvec4));
        }
        k.color = pixelOut(color);
        k.direct = pixelOut(direct);
        k.indirect = pixelOut(indirect);
        k.albedo = pixelOut(albedo);
        k.specAlbedo = pixelOut(specAlbedo);
        k.emission = pixelOut(emission);
        const uint32_t blocksX = (w + kGradientBlock - 1) / kGradientBlock;
        const uint32_t blocksY = (h + kGradientBlock - 1) / kGradientBlock;
        uint64_t rays = 0, dropped = 0, gradientRays = 0;
        if (onDevice || mActive == Backend::Emulated) {
            // Every output, the gradients and their history written by the kernels into the fields' memory, where
            // the graph placed them (nothing is copied here). Placed on cuda: the backend's launches on the GPU;
            // else the same kernels on the CPU threads.
            if (gradientTex) {
                k.gradientHit = pixelOut(gradientHits);
                k.gradientLum = pixelOut(gradientLum);
                k.gradientIndex = ctx.frameIndex();
            }
            const bool replay = gradientTex && !boxFilter && ctx.historyValid() && ctx.frameIndex() > 0;
            // Without last frame's samples (or with box-filtered ones, which are not replayed exactly): zeros.
            if (gradientTex && !replay) gradientTex->clear();
            pt::GradientReplay g;
            if (replay) {
                const auto prevHits = fieldView<glm::uvec4>(ctx.historyPrev(kGradientHits), onDevice);
                const auto prevLum = fieldView<float>(ctx.historyPrev(kGradientLuminance), onDevice);
                g.prevHits = prevHits.data;
                g.prevHitsPitch = uint32_t(prevHits.rowPitch / sizeof(glm::uvec4));
                g.prevLum = prevLum.data;
                g.prevLumPitch = uint32_t(prevLum.rowPitch / sizeof(float));
                g.out = pixelOut(fieldView<glm::vec2>(*gradientTex, onDevice));
                // Last frame's camera rays, exactly: its pose and jitter.
                Camera prev = camera;
                prev.world = camera.prevWorld;
                prev.jitter = camera.prevJitter;
                prev.aspect = float(w) / float(h);
                g.prevCam = makeCameraData(prev, w, h);
                g.prevFrame = frame - 1;
                g.prevIndex = ctx.frameIndex() - 1;
                ctx.stats().set("gradientSamples", double(uint64_t(blocksX) * blocksY));
            }
            if (ctx.device() == DeviceKind::Cuda) {
                if (!mCuda) mCuda = std::make_unique<pt::CudaBackend>();
                const pt::CudaBackend::Counts c = mCuda->render(k, replay ? &g : nullptr, mBvh.builds());
                rays = c.rays;
                dropped = c.dropped;
                ctx.stats().set("ms.cudaKernel", c.kernelMs);
            } else {
                std::vector<glm::uvec2> counts(size_t(w) * h);
                k.counts = {counts.data(), w};
                launch2D(DeviceKind::Emulated, w, h, [&](uint32_t x, uint32_t y) { pt::renderPixel(k, x, y); });
                for (const glm::uvec2& c : counts) {
                    rays += c.x;
                    dropped += c.y;
                }
                if (replay) {
                    std::vector<uint32_t> blockRays(size_t(blocksX) * blocksY);
                    launch2D(DeviceKind::Emulated, blocksX, blocksY, [&](uint32_t bx, uint32_t by) {
                        blockRays[size_t(by) * blocksX + bx] = pt::replayGradient(k, g, bx, by);
                    });
                    for (uint32_t r : blockRays) rays += r;
                }
            }
            finishFrame(ctx, spp, rays, dropped, mTris, start);
            return;
        }
        // Placed on the CPU with device cuda: the GPU renders into its own memory and the outputs are copied into
        // the host fields; the gradients replay last frame's samples on the CPU meanwhile.
        std::vector<glm::uvec4> blockHits(gradientTex ? size_t(blocksX) * blocksY : 0);
        {
            const auto t0 = std::chrono::steady_clock::now();
            mCuda->launch(k, mBvh.builds());
            const auto t1 = std::chrono::steady_clock::now();
            // The gradients replay the last frame's samples, which this frame's do not touch: the CPU traces them
            // while the GPU renders.
            if (gradientTex) gradientRays = gradients(ctx, batch, camera, spp, frame, gradientTex, boxFilter);
            const auto t2 = std::chrono::steady_clock::now();
            const pt::CudaBackend::Counts c =
                mCuda->finish(k, gradientTex ? blockHits.data() : nullptr, ctx.frameIndex());
            const auto t3 = std::chrono::steady_clock::now();
            rays = c.rays;
            dropped = c.dropped;
            const auto ms = [](auto a, auto b) { return std::chrono::duration<double, std::milli>(b - a).count(); };
            ctx.stats().set("ms.cudaLaunch", ms(t0, t1));
            ctx.stats().set("ms.cpuGradients", ms(t1, t2));
            ctx.stats().set("ms.cudaFinish", ms(t2, t3));
            ctx.stats().set("ms.cudaKernel", c.kernelMs);
        }
        if (gradientTex) {
            // Each block's sample of this frame, for the next frame's gradients (as the CPU path keeps them).
            parallelFor2D(blocksX, blocksY, [&](const Tile& t) {
                for (uint32_t by = t.y0; by < t.y1; ++by)
                    for (uint32_t bx = t.x0; bx < t.x1; ++bx) {
                        const glm::uvec2 q = gradientPixel(bx, by, ctx.frameIndex(), w, h);
                        gradientHits.at(bx, by) = blockHits[size_t(by) * blocksX + bx];
                        gradientLum.at(bx, by) = gradientLuminance(glm::vec3(color.at(q.x, q.y)));
                    }
            });
        }
        rays += gradientRays;
        finishFrame(ctx, spp, rays, dropped, mTris, start);
        return;
    }
    // Per-tile counters, summed in tile order afterwards (deterministic).
    const uint32_t tilesX = (w + kDefaultTileSize - 1) / kDefaultTileSize;
    const uint32_t tilesY = (h + kDefaultTileSize - 1) / kDefaultTileSize;
    std::vector<uint64_t> tileRays(size_t(tilesX) * tilesY, 0), tileDropped(size_t(tilesX) * tilesY, 0);

    parallelFor2D(w, h, [&](const Tile& tile) {
        const size_t tileIndex = size_t(tile.y0 / kDefaultTileSize) * tilesX + tile.x0 / kDefaultTileSize;
        const uint32_t tw = tile.x1 - tile.x0, th = tile.y1 - tile.y0, tilePixels = tw * th;
        TileScratch& ts = tileScratch();
        ts.resize(tilePixels);
        uint64_t rays = 0, dropped = 0;

        // Primary hits of the tile, row-major within it.
        if (vbuffer.data) {
            for (uint32_t y = tile.y0; y < tile.y1; ++y) {
                for (uint32_t x = tile.x0; x < tile.x1; ++x) {
                    const uint32_t i = (y - tile.y0) * tw + (x - tile.x0);
                    RayHit primary;
                    const glm::uvec4 vb = vbuffer.at(x, y);
                    if (vb.x != kInvalidId) {
                        primary.instance = vb.x;
                        primary.primitive = vb.y;
                        primary.u = bitsToFloat(vb.z);
                        primary.v = bitsToFloat(vb.w);
                    }
                    ts.primary[i] = primary;
                    ts.dir[i] = glm::normalize(pixelRayDir(cam, x, y));
                }
            }
        } else {
            // Camera rays in coherent 4x4 packets. The same (unnormalised) primary ray, rules and coverage keys as
            // GBufferRT, so hits from its vbuffer and from camera rays are bit-identical.
            traceCameraRays(rayScene, cam, tile, cameraRules, uint32_t(ctx.frameIndex()),
                            [&](uint32_t x, uint32_t y, glm::vec3 dir, const RayHit& hit) {
                                const uint32_t i = (y - tile.y0) * tw + (x - tile.x0);
                                ts.primary[i] = hit;
                                ts.dir[i] = glm::normalize(dir);
                            });
            rays += tilePixels;
        }

        // Paths (pixel-major, sample-minor) in batches kept in flight together (a small wavefront): each round
        // shades every live path of the batch, then traces all their shadow rays as one Embree stream, then all
        // their continuation rays as another. Shading runs as a loop over independent paths and Embree gets whole
        // streams. A path's own arithmetic is that of pt::tracePath, and samples are summed per pixel in sample
        // order, so results depend neither on batching nor on threads.
        const uint64_t totalPaths = uint64_t(tilePixels) * spp;
        uint32_t accPixel = 0;  // pixel whose sums are being accumulated
        PixelSum acc;
        uint32_t samplesSeen = 0;
        auto finishPixel = [&](uint32_t i) {
            const uint32_t x = tile.x0 + i % tw, y = tile.y0 + i / tw;
            const double inv = acc.inverse();
            color.at(x, y) = glm::vec4(acc.color(), 1.f);
            if (split) {
                if (direct.data) direct.at(x, y) = glm::vec4(glm::vec3(acc.direct * inv), 1.f);
                if (indirect.data) indirect.at(x, y) = glm::vec4(glm::vec3(acc.indirect * inv), 1.f);
            }
            // This frame's gradient sample of the pixel's block, for the next frame.
            if (gradientHits.data &&
                gradientPixel(x / kGradientBlock, y / kGradientBlock, ctx.frameIndex(), w, h) == glm::uvec2(x, y)) {
                const RayHit& p = ts.primary[i];
                gradientHits.at(x / kGradientBlock, y / kGradientBlock) =
                    glm::uvec4(p.hit() ? p.instance : kInvalidId, p.primitive, floatBits(p.u), floatBits(p.v));
                gradientLum.at(x / kGradientBlock, y / kGradientBlock) = gradientLuminance(acc.color());
            }
            acc = PixelSum{};
        };
        for (uint64_t first = 0; first < totalPaths; first += kPathBatch) {
            const uint32_t count = uint32_t(std::min<uint64_t>(kPathBatch, totalPaths - first));
            for (uint32_t k = 0; k < count; ++k) {
                const uint64_t item = first + k;
                const uint32_t i = uint32_t(item / spp), s = uint32_t(item % spp);
                const uint32_t x = tile.x0 + i % tw, y = tile.y0 + i / tw;
                const pt::PathRng rng(y * w + x, frame, s);
                if (boxFilter) {
                    // A point uniform in the pixel from the path's own key (not one of its dimensions, so the
                    // path's random numbers are those of the centre filter).
                    pt::PathRng pixelRng = rng;
                    pixelRng.key ^= kPixelSampleKey;
                    const glm::vec2 u = pixelRng.next2();
                    const glm::vec3 dir = cameraRayDir(cam, float(x) + u.x, float(y) + u.y);
                    pt::beginPath(ts.paths[k], cam.origin, dir, rng);
                    ts.hits[k] = rayScene.intersect(cam.origin, dir, 0.f, 1e30f, cameraRules);  // culls as camera
                    ++rays;
                } else {
                    pt::beginPath(ts.paths[k], cam.origin, ts.dir[i], rng);
                    ts.hits[k] = ts.primary[i];
                }
            }
            runPaths(batch, ts, count);
            for (uint32_t k = 0; k < count; ++k) {
                const pt::PathResult& r = ts.paths[k].r;
                rays += r.rays;
                // A dropped sample is never written: a NaN would spread through every filter downstream.
                if (!acc.add(r)) ++dropped;
                if (++samplesSeen == spp) {
                    finishPixel(accPixel++);
                    samplesSeen = 0;
                }
            }
        }

        if (wantsPrimary) {
            for (uint32_t i = 0; i < tilePixels; ++i) {
                const uint32_t x = tile.x0 + i % tw, y = tile.y0 + i / tw;
                const RayHit& primary = ts.primary[i];
                const glm::vec3 dir = ts.dir[i];
                glm::vec4 a(0.f), sa(0.f), e(0.f);
                if (primary.hit()) {
                    const SurfaceHit hs =
                        evalSurface(view, primary.instance, primary.primitive, primary.u, primary.v, dir);
                    a = glm::vec4(diffuseAlbedo(hs), 1.f);
                    const float NdotV = glm::clamp(glm::dot(hs.normalW, -dir), 0.f, 1.f);
                    sa = glm::vec4(specularAlbedo(specularF0(hs), NdotV, hs.roughness), 1.f);
                    e = glm::vec4(pt::emittedRadiance(view, hs, dir), 1.f);
                }
                if (albedo.data) albedo.at(x, y) = a;
                if (specAlbedo.data) specAlbedo.at(x, y) = sa;
                if (emission.data) emission.at(x, y) = e;
            }
        }
        tileRays[tileIndex] = rays;
        tileDropped[tileIndex] = dropped;
    });
    uint64_t rays = 0, dropped = 0;
    for (size_t i = 0; i < tileRays.size(); ++i) {
        rays += tileRays[i];
        dropped += tileDropped[i];
    }
    if (gradientTex) rays += gradients(ctx, batch, camera, spp, frame, gradientTex, boxFilter);
    finishFrame(ctx, spp, rays, dropped, mTris, start);
}

}  // namespace loom
