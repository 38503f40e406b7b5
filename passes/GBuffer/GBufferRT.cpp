#include "GBufferRT.h"

#include <algorithm>

#include "GBufferCommon.h"
#include "GBufferKernels.h"
#include "loom/CameraRays.h"
#include "loom/Error.h"
#include "loom/Parallel.h"
#include "loom/RayScene.h"
#include "loom/Scene.h"

namespace loom {

using namespace gbuffer;

void GBufferRT::reflect(Reflection& r, const CompileInfo&) const { reflectChannels(r); }

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

void GBufferRT::setScene(const std::shared_ptr<const Scene>& scene) {
    mScene = scene;
}

std::vector<std::string> GBufferRT::skippedWork() const {
    if (!mSpecialize || !mScene || mScene->features().animatedNodes) return {};
    return {"previous positions of surfaces: no node is animated (motion vectors are the camera's alone)"};
}

namespace {

/// Typed output views; data == nullptr for channels nobody consumes.
struct Outputs {
    ImageView<glm::vec4> posW, normW, faceNormalW, albedo, specAlbedo, emission;
    ImageView<glm::vec2> linearZ, pnFwidth, mvec;
    ImageView<glm::uvec4> vbuffer;
    ImageView<uint32_t> meshId;
};

template <class T>
ImageView<T> viewOf(const PassContext& ctx, const char* name) {
    Texture* t = ctx.output(name);
    return t ? t->view<T>() : ImageView<T>{};
}

void store(const Outputs& o, uint32_t x, uint32_t y, const GBufferSample& g) {
    if (o.posW.data) o.posW.at(x, y) = g.posW;
    if (o.normW.data) o.normW.at(x, y) = g.normW;
    if (o.faceNormalW.data) o.faceNormalW.at(x, y) = g.faceNormalW;
    if (o.linearZ.data) o.linearZ.at(x, y) = g.linearZ;
    if (o.pnFwidth.data) o.pnFwidth.at(x, y) = g.pnFwidth;
    if (o.mvec.data) o.mvec.at(x, y) = g.mvec;
    if (o.albedo.data) o.albedo.at(x, y) = g.albedo;
    if (o.specAlbedo.data) o.specAlbedo.at(x, y) = g.specAlbedo;
    if (o.emission.data) o.emission.at(x, y) = g.emission;
    if (o.vbuffer.data) o.vbuffer.at(x, y) = g.vbuffer;
    if (o.meshId.data) o.meshId.at(x, y) = g.meshId;
}

}  // namespace

void GBufferRT::execute(PassContext& ctx) {
    const Scene* scene = ctx.scene();
    if (!scene || !ctx.camera())
        throwBadInput(ctx.passName(), "GBufferRT needs a scene", "a scene given with --scene",
                      "render with `loom render --scene data/scenes/cornell_box.gltf ...`");
    Outputs o{viewOf<glm::vec4>(ctx, kPosW),       viewOf<glm::vec4>(ctx, kNormW),
              viewOf<glm::vec4>(ctx, kFaceNormalW), viewOf<glm::vec4>(ctx, kAlbedo),
              viewOf<glm::vec4>(ctx, kSpecAlbedo),  viewOf<glm::vec4>(ctx, kEmission),
              viewOf<glm::vec2>(ctx, kLinearZ),     viewOf<glm::vec2>(ctx, kPnFwidth),
              viewOf<glm::vec2>(ctx, kMvec),        viewOf<glm::uvec4>(ctx, kVBuffer),
              viewOf<uint32_t>(ctx, kMeshId)};
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
    auto run = [&]<bool Moving>() {
        parallelFor2D(w, h, [&](const Tile& t) {
            traceCameraRays(rays, cam, t, rules, frame, [&](uint32_t x, uint32_t y, glm::vec3 dir, const RayHit& hit) {
                store(o, x, y,
                      hit.hit() ? hitSample<Moving>(view, cam, x, y, hit.instance, hit.primitive, hit.u, hit.v)
                                : missSample(cam, dir));
            });
        });
    };
    if (moving)
        run.template operator()<true>();
    else
        run.template operator()<false>();
    ctx.stats().set("staticInstances", moving ? 0.0 : 1.0);
}

}  // namespace loom
