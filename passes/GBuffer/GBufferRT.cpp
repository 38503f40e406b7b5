#include "GBufferRT.h"

#include <algorithm>

#include "GBufferCommon.h"
#include "GBufferKernels.h"
#include "loom/Bvh.h"
#include "loom/CameraRays.h"
#include "loom/Error.h"
#include "loom/Parallel.h"
#include "loom/RayScene.h"
#include "loom/Scene.h"

namespace loom {

using namespace gbuffer;

void GBufferRT::reflect(Reflection& r, const CompileInfo&) const {
    reflectChannels(r);
}

void GBufferRT::declareParams(ParamList& p) {
    const gbuffer::Visibility defaults;
    p.addEnum("cullMode", &mVisibility.cullMode, defaults.cullMode, {"none", "back"})
        .doc("skip back faces of single-sided materials (double-sided ones are always hit)");
    p.add("alphaTest", &mVisibility.alphaTest, defaults.alphaTest)
        .doc(
            "alphaMode MASK: rays pass where alpha < alphaCutoff; BLEND: stochastic transparency (the surface is "
            "there with probability alpha); false: every material opaque");
    p.add("specialize", &mSpecialize, true)
        .doc(
            "skip what the frame does not need: where no instance moved since the last frame, motion vectors are "
            "the camera's alone (no previous-position transform); the output is the same bit for bit. false: the "
            "generic kernel, for comparison");
}

GBufferRT::GBufferRT() : mDeviceScene(std::make_unique<device::DeviceScene>()) {}
GBufferRT::~GBufferRT() = default;

bool GBufferRT::runsOn(DeviceKind d) const {
    return d == DeviceKind::Cpu || d == DeviceKind::Emulated || (d == DeviceKind::Cuda && device::launchesOnCuda());
}

void GBufferRT::setScene(const std::shared_ptr<const Scene>& scene) {
    mScene = scene;
}

std::vector<std::string> GBufferRT::skippedWork() const {
    if (!mSpecialize || !mScene || mScene->features().animatedNodes) return {};
    return {"previous positions of surfaces: no node is animated (motion vectors are the camera's alone)"};
}

namespace {

/// The view of output `name` where this pass's kernels reach it: a host view on the CPU (which fails for device
/// memory), the device view elsewhere; empty for a channel nobody consumes.
template <class T>
ImageView<T> viewOf(const PassContext& ctx, const char* name) {
    Texture* t = ctx.output(name);
    if (!t) return ImageView<T>{};
    return ctx.device() == DeviceKind::Cpu ? t->view<T>() : t->deviceView<T>();
}

GBufferViews outputViews(const PassContext& ctx) {
    return GBufferViews{
        viewOf<glm::vec4>(ctx, kPosW),     viewOf<glm::vec4>(ctx, kNormW),      viewOf<glm::vec4>(ctx, kFaceNormalW),
        viewOf<glm::vec4>(ctx, kAlbedo),   viewOf<glm::vec4>(ctx, kSpecAlbedo), viewOf<glm::vec4>(ctx, kEmission),
        viewOf<glm::vec2>(ctx, kLinearZ),  viewOf<glm::vec2>(ctx, kPnFwidth),   viewOf<glm::vec2>(ctx, kMvec),
        viewOf<glm::uvec4>(ctx, kVBuffer), viewOf<uint32_t>(ctx, kMeshId)};
}

}  // namespace

void GBufferRT::execute(PassContext& ctx) {
    const Scene* scene = ctx.scene();
    if (!scene || !ctx.camera())
        throwBadInput(ctx.passName(), "GBufferRT needs a scene", "a scene given with --scene",
                      "render with `loom render --scene data/scenes/cornell_box.gltf ...`");
    const GBufferViews o = outputViews(ctx);
    const uint32_t w = ctx.frameWidth(), h = ctx.frameHeight();
    Camera camera = *ctx.camera();
    camera.aspect = float(w) / float(h);
    const CameraData cam = makeCameraData(camera, w, h);
    const SceneView& view = scene->view();
    const RayScene& rays = scene->rayScene();
    // Culling and alpha testing are RayScene's (RayRules), for the coherent 4x4 packets too; the path tracer's
    // camera rays use the same rules and coverage keys, so they agree with this vbuffer bit for bit.
    const uint32_t rules = (mVisibility.cullMode == CullMode::Back ? kRayCullBackFaces : 0u) |
                           (mVisibility.alphaTest ? kRayAlphaTest : 0u);
    const uint32_t frame = uint32_t(ctx.frameIndex());
    // Decided once per frame: whether any instance moved since the last one (its prevWorld differs from its world).
    const bool moving = !mSpecialize || std::any_of(scene->instances.begin(), scene->instances.end(),
                                                    [](const Instance& i) { return i.prevWorld != i.world; });
    ctx.stats().set("staticInstances", moving ? 0.0 : 1.0);
    if (ctx.device() != DeviceKind::Cpu) {
        // The same rays, rules and keys as traceCameraRays below, through the BVH.
        const bool keyed = (rules & kRayAlphaTest) && rays.hasAlphaTestedGeometry();
        executeOnDevice(ctx, *scene, device::TraceParams{cam, w, h, rules, frame, keyed, moving}, o);
        return;
    }
    auto run = [&]<bool Moving>() {
        parallelFor2D(w, h, [&](const Tile& t) {
            traceCameraRays(rays, cam, t, rules, frame, [&](uint32_t x, uint32_t y, glm::vec3 dir, const RayHit& hit) {
                storeSample(o, x, y,
                            hit.hit() ? hitSample<Moving>(view, cam, x, y, hit.instance, hit.primitive, hit.u, hit.v)
                                      : missSample(cam, dir));
            });
        });
    };
    if (moving)
        run.template operator()<true>();
    else
        run.template operator()<false>();
}


void GBufferRT::executeOnDevice(PassContext& ctx, const Scene& scene, const device::TraceParams& params,
                                const GBufferViews& out) {
    const BvhView host = mBvh.update(scene).view(scene.view());
    device::trace(ctx.device(), mDeviceScene->view(ctx.device(), host, mBvh.builds()), params, out);
}

}  // namespace loom
